"""Metadata schema: validation names the key, JSON/YAML round trips, decode."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk

from .conftest import base_metadata


def test_round_trip_through_json() -> None:
    m = sdk.ModelMetadata.from_dict(base_metadata(provenance={"scenes": ["a", "b"], "val": {"r2": 0.8}}))
    again = sdk.ModelMetadata.from_json(m.to_json())
    assert again == m
    assert again.to_dict()["provenance"] == {"scenes": ["a", "b"], "val": {"r2": 0.8}}
    assert json.loads(m.to_json())["schema_version"] == 1  # the lowest schema that holds its fields


def test_numpy_numbers_are_numbers() -> None:
    """A mu_y or threshold computed with numpy (np.float32) was "expected a finite number, got np.float32(0.08)", a
    tile size np.int64(16) "expected one of (1, ..., 16, 32)": taken now, stored as Python's (the JSON needs them)."""
    t = sdk.Transform.clamped(np.float32(0.25))
    assert type(t.mu_y) is float and t.mu_y == pytest.approx(0.25)
    assert sdk.Transform.linear(np.int64(2), np.float64(0.5)).factor == 2.0
    m = sdk.ModelMetadata.from_dict(base_metadata(
        transform={"type": "logistic", "mu_y": np.float32(0.25), "k": np.int32(10)}, tile_size=np.int64(16),
        input_multiple=np.int8(4), default_threshold=np.float32(0.5), safety=np.float64(0.01),
        higher_is_better=np.False_, schema_version=np.int64(2)))
    assert (m.tile_size, m.input_multiple, m.default_threshold, m.higher_is_better) == (16, 4, 0.5, False)
    assert sdk.ModelMetadata.from_json(m.to_json()) == m
    for change, key in (({"safety": np.True_}, "safety"), ({"tile_size": np.float64(16)}, "tile_size"),
                        ({"transform": {"type": "clamped", "mu_y": np.bool_(True)}}, "transform.mu_y"),
                        ({"default_threshold": np.float32("nan")}, "default_threshold")):
        with pytest.raises(sdk.MetadataError) as err:
            sdk.ModelMetadata.from_dict(base_metadata(**change))
        assert err.value.key == key


def test_input_multiple_is_optional_validated_and_raises_the_schema() -> None:
    m = sdk.ModelMetadata.from_dict(base_metadata())
    assert m.input_multiple is None and m.pad_multiple == 16 and "input_multiple" not in m.to_dict()
    m4 = sdk.ModelMetadata.from_dict(base_metadata(input_multiple=4))
    assert m4.input_multiple == 4 and m4.pad_multiple == 4
    d = json.loads(m4.to_json())
    assert d["input_multiple"] == 4 and d["schema_version"] == 2
    assert sdk.ModelMetadata.from_json(m4.to_json()) == m4
    for bad in (3, 32, 0, True, "4", 4.0):
        with pytest.raises(sdk.MetadataError, match="input_multiple") as info:
            sdk.ModelMetadata.from_dict(base_metadata(input_multiple=bad))
        assert info.value.key == "input_multiple"
    with pytest.raises(sdk.MetadataError, match="schema_version"):
        sdk.ModelMetadata.from_dict(base_metadata(schema_version=sdk.SCHEMA_VERSION + 1))


def test_finite_probe_is_optional_validated_and_raises_the_schema() -> None:
    m = sdk.ModelMetadata.from_dict(base_metadata(input_multiple=4))
    assert m.finite_probe is None and "finite_probe" not in m.to_dict()
    p = sdk.ModelMetadata.from_dict(base_metadata(input_multiple=4, finite_probe="finite_probe"))
    d = json.loads(p.to_json())
    assert p.finite_probe == "finite_probe" == d["finite_probe"]
    assert d["schema_version"] == 3
    assert sdk.ModelMetadata.from_json(p.to_json()) == p
    # written with the lowest schema that holds it, whatever the file said
    assert sdk.ModelMetadata.from_dict(base_metadata(schema_version=3)).schema_version == 1
    for bad in ("", "9lives", "a b", "x" * 200, 3, True, ["finite_probe"]):
        with pytest.raises(sdk.MetadataError, match="finite_probe") as info:
            sdk.ModelMetadata.from_dict(base_metadata(finite_probe=bad))
        assert info.value.key == "finite_probe"


def test_tail_is_optional_validated_and_raises_the_schema() -> None:
    """``tail``: the digest of a splitting model's tail graph (schema 4)."""
    digest = "sha256:" + "ab" * 32
    m = sdk.ModelMetadata.from_dict(base_metadata(input_multiple=4, finite_probe="finite_probe"))
    assert m.tail is None and "tail" not in m.to_dict()
    t = sdk.ModelMetadata.from_dict(base_metadata(input_multiple=4, finite_probe="finite_probe", tail=digest))
    d = json.loads(t.to_json())
    assert t.tail == digest == d["tail"]
    assert d["schema_version"] == 4
    assert sdk.ModelMetadata.from_json(t.to_json()) == t
    for bad in ("", "sha256:ab", "md5:" + "ab" * 32, 3, True, [digest]):
        with pytest.raises(sdk.MetadataError, match="tail") as info:
            sdk.ModelMetadata.from_dict(base_metadata(tail=bad))
        assert info.value.key == "tail"


def test_rate_factors_are_optional_validated_and_raise_the_schema() -> None:
    """``rate_factors``: a threshold factor per reduced rate (schema 5, the newest); rates left out keep 1,
    all 1 is no field at all (and no newer schema)."""
    m = sdk.ModelMetadata.from_dict(base_metadata())
    assert m.rate_factors == (1.0,) * 6 and "rate_factors" not in m.to_dict() and m.schema_version == 1
    assert sdk.ModelMetadata.from_dict(base_metadata(rate_factors={"2x2": 1})).schema_version == 1
    assert sdk.ModelMetadata.from_dict(base_metadata(rate_factors=None)) == m
    f = sdk.ModelMetadata.from_dict(base_metadata(rate_factors={"1x2": 1.2, "2x1": 1.2, "4x4": 0.85}))
    d = json.loads(f.to_json())
    assert f.rate_factors == (1.2, 1.2, 1.0, 1.0, 1.0, 0.85)
    assert d["rate_factors"] == {"1x2": 1.2, "2x1": 1.2, "2x2": 1.0, "2x4": 1.0, "4x2": 1.0, "4x4": 0.85}
    assert d["schema_version"] == 5 == sdk.SCHEMA_VERSION  # the newest field: the newest schema
    assert sdk.ModelMetadata.from_json(f.to_json()) == f
    for bad, words in (({"1x1": 2.0}, "unknown rate '1x1'"), ({"3x3": 2.0}, "unknown rate"),
                       ({"2x2": 0.0}, "in \\[0.25, 4\\]"), ({"2x2": 5}, "2x2's factor"), ({"2x2": float("nan")}, "2x2"),
                       ({"2x2": True}, "2x2"), ({"2x2": "1.2"}, "2x2"), ([1.2] * 6, "mapping"), ("1.2", "mapping")):
        with pytest.raises(sdk.MetadataError, match=words) as info:
            sdk.ModelMetadata.from_dict(base_metadata(rate_factors=bad))
        assert info.value.key == "rate_factors"
    with pytest.raises(sdk.MetadataError, match="rate_factors"):  # however the metadata is built
        import dataclasses

        dataclasses.replace(m, rate_factors=(1.0, 1.0))


def test_defaults_and_frozen() -> None:
    m = sdk.ModelMetadata.from_dict(base_metadata())
    assert m.extrapolation_k == 2.13 and m.safety == 0.0 and m.higher_is_better is False
    with pytest.raises(AttributeError):
        m.safety = 1.0  # type: ignore[misc]
    with pytest.raises(TypeError):
        m.provenance["x"] = 1  # type: ignore[index]


def test_a_null_description_is_none_and_any_other_non_string_refused(tmp_path: Path) -> None:
    """`description:` left empty in a sidecar (YAML's null) was refused by rtp-export --metadata and sdk.load
    ("expected a string, got None") while rtp-export --retune took it for no description; it is none everywhere."""
    assert sdk.ModelMetadata.from_dict(base_metadata(description=None)).description == ""
    sidecar = tmp_path / "m.yaml"
    sidecar.write_text("".join(f"{k}: {json.dumps(v)}\n" for k, v in base_metadata().items() if k != "description")
                       + "description:\n", encoding="utf-8")
    assert sdk.ModelMetadata.from_yaml(sidecar).description == ""
    for bad in (0, False, 5, ["x"]):
        with pytest.raises(sdk.MetadataError, match="^description: expected a string") as info:
            sdk.ModelMetadata.from_dict(base_metadata(description=bad))
        assert info.value.key == "description"


def test_psnr_is_higher_is_better_by_default() -> None:
    m = sdk.ModelMetadata.from_dict(base_metadata(metric="psnr", weber_l=None, default_threshold=35.0))
    assert m.higher_is_better is True


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"metric": "JN Yang"}, "metric"),
        ({"metric": "mymetric"}, "higher_is_better"),
        ({"metric": "psnr", "higher_is_better": False, "weber_l": None}, "higher_is_better"),
        ({"tile_size": 12}, "tile_size"),
        ({"tile_size": True}, "tile_size"),
        ({"inputs": []}, "inputs"),
        ({"inputs": ["reprojected.r", "seen", "albedo.red", "normal.z"]}, "inputs"),
        ({"inputs": ["seen", "seen"]}, "inputs"),
        ({"outputs": ["1x2", "2x2"]}, "outputs"),
        ({"default_threshold": "0.25"}, "default_threshold"),
        ({"default_threshold": float("nan")}, "default_threshold"),
        ({"safety": -0.1}, "safety"),
        ({"extrapolation_k": 0.5}, "extrapolation_k"),
        ({"weber_l": None}, "weber_l"),
        ({"schema_version": 99}, "schema_version"),
        ({"provenance": {"when": object()}}, "provenance"),
        ({"safety_margin": 0.1}, "safety_margin"),
        ({"transform": {"type": "clamped"}}, "transform.mu_y"),
    ],
)
def test_validation_errors_name_the_key(change: dict[str, Any], key: str) -> None:
    with pytest.raises(sdk.MetadataError) as info:
        sdk.ModelMetadata.from_dict(base_metadata(**change))
    assert info.value.key == key
    assert str(info.value).startswith(key)
    assert isinstance(info.value, ValueError)


def test_missing_required_fields() -> None:
    for field in ("metric", "transform", "tile_size", "inputs", "outputs", "default_threshold"):
        d = base_metadata()
        del d[field]
        with pytest.raises(sdk.MetadataError) as info:
            sdk.ModelMetadata.from_dict(d)
        assert field in str(info.value)


@pytest.mark.parametrize(("field", "guess"), [("default_treshold", "default_threshold"), ("tile", "tile_size"),
                                               ("zzz", None)])
def test_an_unknown_field_is_named_with_the_nearest_known_one(field: str, guess: str | None) -> None:
    """A sidecar's misspelt field is refused by name, with the field it most likely meant (a field's start, 'tile',
    is that field); none is guessed where none is close."""
    with pytest.raises(sdk.MetadataError) as info:
        sdk.ModelMetadata.from_dict({**base_metadata(), field: 1})
    assert info.value.key == field and str(info.value).startswith(f"{field}: unknown metadata field")
    assert ("did you mean" in str(info.value)) == (guess is not None)
    if guess:
        assert f"(did you mean {guess}?)" in str(info.value)


def test_invalid_json_is_a_metadata_error() -> None:
    with pytest.raises(sdk.MetadataError, match="not valid JSON"):
        sdk.ModelMetadata.from_json("{'metric': 'flip'}")  # a Python repr is not JSON, and is never evaluated


def test_yaml_sidecar(tmp_path: Path) -> None:
    p = tmp_path / "side.yaml"
    p.write_text(
        "metric: flip\ntransform: {type: linear, factor: 2.0, offset: 0.0}\ntile_size: 8\n"
        "inputs: [reprojected.r, seen, albedo.r, normal.z]\noutputs: ['2x2']\ndefault_threshold: 0.1\n"
    )
    m = sdk.ModelMetadata.from_yaml(p)
    assert m.metric == "flip" and m.transform.factor == 2.0 and m.outputs == ("2x2",)
    with pytest.raises(sdk.ModelNotFoundError):
        sdk.ModelMetadata.from_yaml(tmp_path / "missing.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("metric: [unclosed\n")
    with pytest.raises(sdk.MetadataError, match="not valid YAML"):
        sdk.ModelMetadata.from_yaml(bad)
    # the file is named: a model given for its sidecar (YAML reads its text as a string), a field that is wrong
    bad.write_text("hello\n")
    with pytest.raises(sdk.MetadataError, match=r"bad.yaml: expected a YAML sidecar, a mapping of .* got a str"):
        sdk.ModelMetadata.from_yaml(bad)
    bad.write_text(p.read_text().replace("tile_size: 8", "tile_size: 12"))
    with pytest.raises(sdk.MetadataError, match=r"bad.yaml: tile_size: expected one of") as info:
        sdk.ModelMetadata.from_yaml(bad)
    assert info.value.key == "tile_size"


def test_a_yaml_sidecar_reads_exponents_as_numbers_dates_as_text_and_refuses_a_key_given_twice(
        tmp_path: Path) -> None:
    """PyYAML reads YAML 1.1: `weber_l: 1e-10` (the paper's l as docs/export.md writes it) was the string '1e-10',
    refused as "expected a finite number, got '1e-10'"; a provenance date a datetime.date, "not JSON serializable";
    and a field given twice kept its last value without a word (a second `default_threshold:` line)."""
    p = tmp_path / "side.yaml"
    p.write_text("metric: jnyang\ntransform: {type: logistic, mu_y: 2.5E-1, k: 1e1}\ntile_size: 16\nsafety: 1e-3\n"
                 "inputs: [reprojected.r, seen, albedo.r, normal.z]\noutputs: [1x2, 2x1]\ndefault_threshold: 2e-1\n"
                 "weber_l: 1e-10\nprovenance: {trained: 2026-12-01, lr: -5e-4, commit: 4e12345, step: 1.5}\n")
    m = sdk.ModelMetadata.from_yaml(p)
    assert (m.transform.mu_y, m.transform.k, m.safety, m.default_threshold, m.weber_l) == (0.25, 10.0, 1e-3, 0.2, 1e-10)
    # (the free-form provenance keeps what only YAML 1.2 reads as a number as its text: an unquoted git hash such as
    # 4e12345 was the float inf there, refused as "not JSON compliant")
    assert m.provenance == {"trained": "2026-12-01", "lr": "-5e-4", "commit": "4e12345", "step": 1.5}
    assert type(m.safety) is float and type(m.transform.k) is float
    p.write_text(p.read_text() + "default_threshold: 0.3\n")
    with pytest.raises(sdk.MetadataError, match=r"'default_threshold' given twice, first on line 7 .*line 10"):
        sdk.ModelMetadata.from_yaml(p)
    p.write_text(p.read_text().replace("default_threshold: 0.3\n", "").replace("lr: -5e-4", "lr: 1, lr: 2"))
    with pytest.raises(sdk.MetadataError, match=r"'lr' given twice"):
        sdk.ModelMetadata.from_yaml(p)


def test_decode_applies_safety_inverse_and_extrapolation() -> None:
    m = sdk.ModelMetadata.from_dict(base_metadata(safety=0.05, outputs=["1x2", "2x1"]))
    raw = np.array([0.2, 0.4]).reshape(2, 1, 1)
    got = m.decode(raw)[:, 0, 0]
    e12, e21 = 2 * 0.25 * 0.25, 2 * 0.25 * 0.45  # (raw + safety) * 2 mu
    np.testing.assert_allclose(got[:2], [e12, e21], rtol=1e-6)
    np.testing.assert_allclose(got[4], 2.13 * e21, rtol=1e-6)
    assert got.dtype == np.float32


@pytest.mark.parametrize("outputs", [list(s) for s in sdk.OUTPUT_SETS])
@pytest.mark.parametrize("metric", ["jnyang", "psnr"])
def test_saturation_is_the_worst_value_decode_can_give_at_any_rate(outputs: list[str], metric: str) -> None:
    """From two outputs (or 2x2 alone) the extrapolated 2x4, 4x2 and 4x4 reach k times the decoded worst output: the
    saturation was that worst output, and a threshold between the two was said to pass every tile at every rate."""
    hib = metric == "psnr"
    m = sdk.ModelMetadata.from_dict(base_metadata(
        metric=metric, outputs=outputs, safety=0.05, weber_l=None if hib else 0.02,
        transform={"type": "clamped", "mu_y": 40.0 if hib else 0.25}, default_threshold=30 if hib else 0.2))
    worst = np.full((len(outputs), 1, 1), 0.0 if hib else 1.0)  # (PSNR's worst is the smallest output)
    decoded = m.decode(worst)[:, 0, 0]
    np.testing.assert_allclose(m.rate_saturations, decoded, rtol=1e-6)
    assert m.saturation == pytest.approx(float(decoded.min() if hib else decoded.max()), rel=1e-6)
    if len(outputs) <= 2:  # (the extrapolated coarse rates: k times the amplitude, 20 log10 k dB lower)
        own = m.transform.inverse(-0.05 if hib else 1.05)
        assert m.saturation == pytest.approx(own - 20 * np.log10(2.13) if hib else 2.13 * own)


def test_safety_is_conservative_for_every_direction() -> None:
    # PSNR with a linear transform trained on 1 - 0.015 PSNR (the paper's published model): the
    # margin must lower the predicted PSNR.
    psnr = sdk.ModelMetadata.from_dict(
        base_metadata(metric="psnr", weber_l=None, transform={"type": "linear", "factor": -0.015, "offset": 1.0},
                      safety=0.03, outputs=["2x2"], default_threshold=30)
    )
    no_margin = sdk.ModelMetadata.from_dict({**psnr.to_dict(), "safety": 0.0})
    raw = np.full((1, 1, 1), 0.4)
    assert psnr.decode(raw)[2, 0, 0] < no_margin.decode(raw)[2, 0, 0]
    # JNFLIP trained inverted (raw = 1 - T): the margin must raise the predicted error.
    jnflip = sdk.ModelMetadata.from_dict(
        base_metadata(metric="jnflip", transform={"type": "linear", "factor": -0.25, "offset": 1.0}, safety=0.05,
                      outputs=["2x2"])
    )
    assert jnflip.decode(raw)[2, 0, 0] > 4 * (1 - 0.4)
