"""Transforms, inverses and extrapolation: known values, round trips, numpy == torch twins."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch

from rtp import sdk
from rtp.train import transforms as tt


def _cases(vectors: dict[str, Any]) -> list[dict[str, Any]]:
    return vectors["clamped"] + vectors["logistic"] + vectors["linear"]


def test_forward_and_inverse_known_values(vectors: dict[str, Any]) -> None:
    for case in _cases(vectors):
        t = sdk.Transform.from_dict(case["params"])
        np.testing.assert_allclose(t.forward(np.array(case["y"])), case["t"], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(t.inverse(np.array(case["p"])), case["inv"], rtol=1e-7, atol=1e-9)


def test_torch_twins_match_the_same_vectors(vectors: dict[str, Any]) -> None:
    for case in _cases(vectors):
        t = sdk.Transform.from_dict(case["params"])
        got_t = tt.forward(torch.tensor(case["y"], dtype=torch.float64), t).numpy()
        got_i = tt.inverse(torch.tensor(case["p"], dtype=torch.float64), t).numpy()
        np.testing.assert_allclose(got_t, case["t"], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(got_i, case["inv"], rtol=1e-7, atol=1e-9)


@pytest.mark.parametrize(
    "params",
    [
        {"type": "clamped", "mu_y": 0.1},
        {"type": "logistic", "mu_y": 0.3, "k": 10.0},
        {"type": "linear", "factor": -0.25, "offset": 1.0},
    ],
)
def test_round_trip_inside_the_unclamped_range(params: dict[str, Any]) -> None:
    t = sdk.Transform.from_dict(params)
    y = np.linspace(0.0, 0.19, 50) if params["type"] == "clamped" else np.linspace(0.0, 1.0, 50)
    if params["type"] == "linear":
        y = np.linspace(0.0, 4.0, 50)
    np.testing.assert_allclose(t.inverse(t.forward(y)), y, atol=1e-6)


def test_clamped_transform_saturates_and_its_inverse_does_not_clamp() -> None:
    t = sdk.Transform.clamped(0.1)
    assert t.forward(5.0) == 1.0 and t.forward(-1.0) == 0.0
    assert t.inverse(1.5) == pytest.approx(0.3)


def test_logistic_inverse_stays_finite_outside_its_domain() -> None:
    t = sdk.Transform.logistic(0.25, 10.0)
    out = t.inverse(np.array([-5.0, 5.0]))
    assert np.all(np.isfinite(out)) and out[0] < 0 < 0.25 < out[1]


@pytest.mark.parametrize(("mu_y", "k"), [(0.8, 1000.0), (0.05, 20000.0), (0.5, 1e6)])
def test_torch_twins_of_a_steep_logistic_match_the_sdk(mu_y: float, k: float) -> None:
    """A logistic transform with ``k * mu_y`` past 709, which the SDK takes (its span over [0, 1] is about 1):
    the torch twins' bounds were ``1 / (1 + exp(k * mu_y))``, an OverflowError at the first training step."""
    t = sdk.Transform.logistic(mu_y, k)
    y = np.array([0.0, mu_y - 1e-3, mu_y, mu_y + 1e-3, 1.0, 2.0])
    p = np.array([0.0, 0.2, 0.5, 0.8, 1.0])
    np.testing.assert_allclose(tt.forward(torch.tensor(y), t).numpy(), t.forward(y), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(tt.inverse(torch.tensor(p), t).numpy(), t.inverse(p), rtol=1e-9, atol=1e-12)


def test_extrapolation_matches_hand_computed_paper_values(vectors: dict[str, Any]) -> None:
    for case in vectors["extrapolation"]:
        v = np.array(case["values"], dtype=np.float64).reshape(-1, 1, 1)
        got = sdk.extrapolate(v, case["outputs"], 2.13, higher_is_better=case["higher_is_better"])
        np.testing.assert_allclose(got[:, 0, 0], case["expected"], rtol=1e-9)
        got_t = tt.extrapolate(
            torch.tensor(v), case["outputs"], 2.13, higher_is_better=case["higher_is_better"]
        ).numpy()
        np.testing.assert_allclose(got_t[:, 0, 0], case["expected"], rtol=1e-9)


def test_two_output_extrapolation_follows_the_equation_step_by_step() -> None:
    # Section 4.3: 2x2 = max(1x2, 2x1); 2x4 from 1x2 (times k) and 2x2; 4x2 from 2x1 and 2x2; 4x4 from both.
    rng = np.random.default_rng(3)
    v = rng.random((2, 5, 7))
    k = 2.13
    e12, e21 = v
    e22 = np.maximum(e12, e21)
    e24 = np.maximum(k * e12, e22)
    e42 = np.maximum(k * e21, e22)
    expected = np.stack([e12, e21, e22, e24, e42, np.maximum(e24, e42)])
    np.testing.assert_allclose(sdk.extrapolate(v, ("1x2", "2x1")), expected)
    # The anchors' ExtrapolatePerceptuals form gives the same numbers.
    np.testing.assert_allclose(e24, np.maximum(k * e12, e21))


def test_extrapolation_rejects_an_unsupported_output_set() -> None:
    with pytest.raises(sdk.MetadataError, match="cannot extrapolate"):
        sdk.extrapolate(np.zeros((3, 1, 1)), ("1x2", "2x1", "2x2"))


@pytest.mark.parametrize(
    ("params", "key"),
    [
        ({"type": "clamped"}, "transform.mu_y"),
        ({"type": "clamped", "mu_y": 0}, "transform.mu_y"),
        ({"type": "logistic", "mu_y": 0.2}, "transform.k"),
        ({"type": "linear", "factor": 0, "offset": 0}, "transform.factor"),
        ({"type": "cubic"}, "transform.type"),
        ({"type": "clamped", "mu_y": "0.2"}, "transform.mu_y"),
        ({"type": "clamped", "mu_y": 0.2, "k": 3}, "transform.k"),
    ],
)
def test_bad_transform_parameters_name_the_key(params: dict[str, Any], key: str) -> None:
    with pytest.raises(sdk.MetadataError) as info:
        sdk.Transform.from_dict(params)
    assert info.value.key == key and key in str(info.value)
