"""``rtp import``: a dataset from an engine's frames (rtp.capture.import_frames), checked against what the
reference renderer's own capture stores for the same frames, then trained on and evaluated."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.capture import DatasetError, DatasetReader, TargetStore, import_frames
from rtp.cli import main as rtp_main

pytestmark = pytest.mark.gl

W, H = 96, 64


def render_frames(folder: Path, count: int = 3, scene: str = "procedural:0", seed: int = 0,
                  drop: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    """``count`` frames along a camera path, saved as an engine would dump them (G-buffers and every rate),
    without the arrays ``drop`` names; returns the renderer's frames (their shader reprojection, for
    comparison)."""
    from rtp.capture import load_scene
    from rtp.capture.paths import camera_path
    from rtp.cli._predict import _frame_arrays, _save_frame
    from rtp.plugins.moderngl import Renderer

    folder.mkdir(parents=True, exist_ok=True)
    scn, blockers = load_scene(scene, None, None, None)
    path = camera_path(scn, count + 1, "fast", seed, blockers=blockers)
    out = []
    with Renderer(W, H) as r:
        r.load_scene(scn)
        prev = r.render(path.cameras[0])
        for i, (prev_cam, cam) in enumerate(zip(path.cameras, path.cameras[1:])):
            cur = r.render(cam, prev)
            arrays = _frame_arrays(prev, cur, prev_cam, cam, (W, H))
            arrays.update({f"final_{rate}": cur.colour[rate] for rate in sdk.ALL_RATES})
            _save_frame(folder / f"frame_{i:04d}.npz", {k: v for k, v in arrays.items() if k not in drop})
            out.append({"reprojected": cur.reprojected, "seen": cur.seen, "arrays": arrays})
            prev = cur
    return out


@pytest.fixture(scope="module")
def dumps(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict[str, Any]], list[dict[str, Any]]]:
    root = tmp_path_factory.mktemp("dumps")
    a = render_frames(root / "level_a", 3, "procedural:0")
    b = render_frames(root / "level_b", 3, "procedural:3", seed=1)
    return root, a, b


def test_imported_samples_are_what_the_reference_capture_stores(dumps: Any, tmp_path: Path) -> None:
    root, a, b = dumps
    report = import_frames([root / "level_a", root / "level_b"], tmp_path / "data")
    assert (report.written, report.skipped, report.absent) == (6, 0, ()) and not report.warnings
    reader = DatasetReader(tmp_path / "data")
    assert reader.ids == [f"level_{x}-frame_{i:04d}" for x in "ab" for i in range(3)]
    assert reader.manifest["settings"] == {"size": [W, H], "source": "engine frames", "absent": [], "conventions": {
        "albedo_linear": False, "normal_space": "view", "depth_kind": "linear", "tolerance": 0.02}}
    seen_pixels = differ = 0
    for sid, frame in zip(reader.ids, a + b):
        s = reader[sid]
        arrays = frame["arrays"]
        assert s.meta["scene"] == sid.split("-")[0] and s.meta["profile"] == "engine"
        assert s.meta["source"] == sid.split("-")[1] + ".npz"
        q = 1 / 510 + 1e-6  # (uint8 storage)
        for name in ("albedo", "roughness", "metallic", "specular", "shadow", "emissive"):
            np.testing.assert_allclose(s.buffer(name), arrays[name], atol=q, err_msg=name)
        for rate in sdk.ALL_RATES:
            np.testing.assert_allclose(s.final(rate), arrays[f"final_{rate}"], atol=q)
        np.testing.assert_allclose(s.buffer("normal"), arrays["normal"], atol=1e-3)  # (float16)
        np.testing.assert_allclose(s.buffer("depth"), arrays["depth"], rtol=1e-3)
        np.testing.assert_allclose(s.buffer("motion"), arrays["motion"], atol=0.05)
        # the SDK's reprojection against the renderer's shader: the same but for pixels within rounding of an edge
        seen = s.channel("seen") > 0.5
        differ += int((seen != (frame["seen"] > 0.5)).sum())
        seen_pixels += seen.size
        both = seen & (frame["seen"] > 0.5)
        np.testing.assert_allclose(s.buffer("reprojected")[both], frame["reprojected"][both], atol=q)
        geo = arrays["depth"] > 0
        assert s.meta["unseen"] == pytest.approx(1 - seen[geo].mean(), abs=1e-6)
    assert differ <= 0.002 * seen_pixels, differ


def test_an_import_resumes_and_refuses_to_mix(dumps: Any, tmp_path: Path) -> None:
    root, _, _ = dumps
    data = tmp_path / "data"
    assert import_frames(root / "level_a", data).written == 3
    again = import_frames([root / "level_a", root / "level_b"], data)
    assert (again.written, again.skipped) == (3, 3)
    with pytest.raises(DatasetError, match="other settings.*conventions"):
        import_frames(root / "level_a", data, normal_space="world")
    from rtp.capture import capture

    captured = tmp_path / "captured"
    capture(["procedural:1"], captured, per_scene=1, size=(W, H))
    with pytest.raises(DatasetError, match="a dataset the reference renderer captured"):
        import_frames(root / "level_a", captured)
    assert len(DatasetReader(captured).ids) == 2


def test_an_import_into_a_folder_that_holds_nothing_yet_takes_its_settings(dumps: Any, tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """An import killed before its first sample left its manifest (its conventions); the rerun with a corrected
    flag was refused as "captured with other settings" until the folder was deleted. A folder that holds no sample
    takes the rerun's settings, source and profile included (a capture's folder, left empty), as a new one would;
    under the writer lock only: while another job holds it, the folder is left as it was."""
    import shutil

    from rtp.capture import DatasetWriter
    from rtp.sdk.files import writer_lock

    root, _, _ = dumps
    data = tmp_path / "data"

    def killed(*a: Any, **k: Any) -> None:
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(DatasetWriter, "write", killed)
        with pytest.raises(KeyboardInterrupt):
            import_frames(root / "level_a", data)
    assert DatasetReader(data).ids == []
    with writer_lock(data, "rtp import", RuntimeError):  # (another job's: nothing replaced before the lock)
        with pytest.raises(DatasetError, match="being written by another job"):
            import_frames(root / "level_a", data, normal_space="world")
    assert DatasetReader(data).manifest["settings"]["conventions"]["normal_space"] == "view"
    report = import_frames(root / "level_a", data, normal_space="world")
    assert report.written == 3
    assert DatasetReader(data).manifest["settings"]["conventions"]["normal_space"] == "world"
    # a capture's folder (another source), a folder of another profile, left empty: taken as new
    for settings in ({"size": [W, H], "renderer": "rtp.plugins.moderngl reference deferred renderer"},
                     {"size": [W, H], "source": "engine frames", "profile": "other", "absent": []}):
        empty = tmp_path / "empty"
        DatasetWriter(empty, settings)
        assert import_frames(root / "level_a", empty).written == 3
        assert DatasetReader(empty).manifest["settings"]["source"] == "engine frames"
        assert "profile" not in DatasetReader(empty).manifest["settings"]
        with pytest.raises(DatasetError, match="other settings"):  # (with samples: refused, as before)
            import_frames(root / "level_a", empty, normal_space="world")
        shutil.rmtree(empty)


def test_the_next_commands_an_import_prints_quote_the_dataset_path(dumps: Any, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp import ... --out "out é/da ta"` ended with "next: rtp targets out é/da ta, ...": copied into a shell,
    the command named two folders. The path is quoted for a shell (a plain one is printed as it is)."""
    import shlex

    root, _, _ = dumps
    for out in (tmp_path / "out é" / "da ta", tmp_path / "plain"):
        assert rtp_main(["import", str(root / "level_a"), "--out", str(out), "--quiet"]) == 0
        line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("next: "))
        targets, train = line.removeprefix("next: ").split(" (validation")[0].split(", then ")
        assert shlex.split(targets) == ["rtp", "targets", str(out)], line
        assert shlex.split(train) == ["rtp", "train", "--data", str(out), "--metric", "jnyang", "--out", "model.pt"]
        assert (f"rtp targets {out}," in line) == (out.name == "plain"), line


def test_a_resumed_import_with_another_profile_is_refused(dumps: Any, tmp_path: Path) -> None:
    """--profile was not in the manifest's settings: a resumed import with another one mixed both across the
    samples of one folder."""
    import json

    root, _, _ = dumps
    data, other = tmp_path / "data", tmp_path / "other"
    assert import_frames(root / "level_a", data).written == 3  # (the default, engine: recorded as before, not at all)
    assert "profile" not in DatasetReader(data).manifest["settings"]
    with pytest.raises(DatasetError, match=r"data was imported with --profile engine, not handheld: .*give --profile "
                                           r"engine to grow it"):
        import_frames(root / "level_b", data, profile="handheld")
    assert len(DatasetReader(data).ids) == 3
    assert import_frames(root / "level_a", other, profile="handheld").written == 3
    assert DatasetReader(other).manifest["settings"]["profile"] == "handheld"
    with pytest.raises(DatasetError, match="other was imported with --profile handheld, not engine"):
        import_frames(root / "level_b", other)
    assert import_frames(root / "level_b", other, profile="handheld").written == 3
    assert {s.meta["profile"] for s in DatasetReader(other)} == {"handheld"}
    # a folder imported before the profile was recorded: its samples' profile is the folder's
    manifest = json.loads((other / "manifest.json").read_text())
    del manifest["settings"]["profile"]
    (other / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DatasetError, match="other was imported with --profile handheld, not engine"):
        import_frames(root / "level_a", other)
    assert import_frames(root / "level_a", other, profile="handheld").skipped == 3


def test_bad_frames_are_named_before_anything_is_written(dumps: Any, tmp_path: Path) -> None:
    root, _, _ = dumps
    data = tmp_path / "data"
    render_frames(tmp_path / "nofinal", 1, drop=("final_2x4",))
    render_frames(tmp_path / "small", 1)
    cases = [
        ([tmp_path / "nofinal"], "lacks final_2x4"),
        ([tmp_path / "none.npz"], "no such file"),
        ([tmp_path / "empty"], "a folder with no .npz frame"),
        ([root / "level_a", tmp_path / "small"], None),  # (the same size: fine, checked below)
    ]
    (tmp_path / "empty").mkdir()
    for frames, match in cases[:3]:
        with pytest.raises(sdk.ParameterError, match=match):
            import_frames(frames, data)
        assert not (data / "samples").exists() or not any((data / "samples").iterdir())
    # another size; another file's name twice under one --scene; a scene name no id can hold
    from rtp.cli._predict import _save_frame

    big = dict(np.load(root / "level_a" / "frame_0000.npz"))
    big = {k: (np.repeat(np.repeat(v, 2, 0), 2, 1) if v.ndim >= 2 and v.shape[:2] == (H, W) else v)
           for k, v in big.items()}
    (tmp_path / "big").mkdir()
    _save_frame(tmp_path / "big" / "frame_0000.npz", big)
    with pytest.raises(sdk.ParameterError, match=r"of 2 sizes \(96x64: 3, 192x128: 1\)"):
        import_frames([root / "level_a", tmp_path / "big"], data)
    with pytest.raises(sdk.ParameterError, match="two files make the sample id 'x-frame_0000'"):
        import_frames([root / "level_a", root / "level_b"], data, scene="x")
    with pytest.raises(sdk.ParameterError, match="scene: expected a name"):
        import_frames(root / "level_a", data, scene="my level")
    assert not (data / "samples").exists() or not any((data / "samples").iterdir())
    # a later frame's final image of another size: refused from its header before the first sample is written
    (tmp_path / "half").mkdir()
    half = dict(np.load(root / "level_a" / "frame_0001.npz"))
    _save_frame(tmp_path / "half" / "frame_0001.npz", {**half, "final_2x2": half["final_2x2"][::2, ::2]})
    with pytest.raises(sdk.ParameterError, match=r"frame_0001.npz': final_2x2 has shape \(32, 48, 3\), expected "
                                                 r"\(64, 96, 3\) \(or RGBA, 4\): final_1x1's size"):
        import_frames([root / "level_a" / "frame_0000.npz", tmp_path / "half"], data)
    assert not (data / "samples").exists() or not any((data / "samples").iterdir())
    # a final image that is not a display-encoded frame
    hdr = dict(np.load(root / "level_a" / "frame_0000.npz"))
    hdr["final_4x4"] = hdr["final_4x4"] * 4.0
    (tmp_path / "hdr").mkdir()
    _save_frame(tmp_path / "hdr" / "frame_0000.npz", hdr)
    with pytest.raises(sdk.ParameterError, match="final_4x4 has values in .*display-encoded"):
        import_frames(tmp_path / "hdr", tmp_path / "hdrdata")


def test_uint8_and_rgba_finals_are_taken_as_a_read_back_gives_them(dumps: Any, tmp_path: Path) -> None:
    root, _, _ = dumps
    frame = dict(np.load(root / "level_a" / "frame_0000.npz"))
    rgba = dict(frame)
    for rate in sdk.ALL_RATES:
        v = frame[f"final_{rate}"]
        rgba[f"final_{rate}"] = np.concatenate([np.round(v * 255), np.full(v.shape[:2] + (1,), 255)], -1).astype(np.uint8)
    (tmp_path / "rgba").mkdir()
    np.savez(tmp_path / "rgba" / "frame_0000.npz", **rgba)
    import_frames(tmp_path / "rgba", tmp_path / "d1")
    import_frames(root / "level_a" / "frame_0000.npz", tmp_path / "d2", scene="rgba")
    a, b = DatasetReader(tmp_path / "d1"), DatasetReader(tmp_path / "d2")
    for rate in sdk.ALL_RATES:
        np.testing.assert_array_equal(a[a.ids[0]].final(rate), b[b.ids[0]].final(rate))


def test_frames_without_some_g_buffers_import_and_their_channels_are_refused(tmp_path: Path) -> None:
    render_frames(tmp_path / "lvl", 2, drop=("shadow", "emissive", "metallic"))
    report = import_frames(tmp_path / "lvl", tmp_path / "data")
    assert report.absent == ("metallic", "shadow", "emissive")
    reader = DatasetReader(tmp_path / "data")
    assert reader.absent == {"metallic", "shadow", "emissive"}
    s = reader[reader.ids[0]]
    assert s.inputs(["reprojected.y", "seen", "albedo.y", "normal.z", "roughness", "specular"]).shape == (6, H, W)
    for channel in ("shadow", "metallic", "emissive"):
        with pytest.raises(DatasetError, match=f"channel '{channel}': this dataset has no"):
            s.inputs(["seen", channel])
    from rtp.capture import preview_sheet

    assert preview_sheet(s).ndim == 3  # (its panels of absent G-buffers say so instead of failing)
    # every frame the same G-buffers: some with shadow, some without, is refused
    render_frames(tmp_path / "lvl2", 1)
    with pytest.raises(sdk.ParameterError, match="1 of 3 hold 'metallic'"):
        import_frames([tmp_path / "lvl", tmp_path / "lvl2"], tmp_path / "data2")


def test_frames_of_which_only_some_hold_motion_are_refused_naming_the_first_that_differs(dumps: Any,
                                                                                         tmp_path: Path) -> None:
    root, _, _ = dumps
    from rtp.cli._predict import _save_frame

    data = tmp_path / "data"
    assert import_frames(root / "level_a", data).written == 3
    before = sorted(p.name for p in (data / "samples").iterdir())
    nomotion = tmp_path / "nomotion"  # the engine's motion vectors dumped on some frames only
    nomotion.mkdir()
    for f in sorted((root / "level_b").glob("*.npz"))[:2]:
        arrays = dict(np.load(f))
        if f.name == "frame_0001.npz":
            del arrays["motion"]
        _save_frame(nomotion / f.name, arrays)
    with pytest.raises(sdk.ParameterError, match=r"nomotion/frame_0001.npz' lacks motion, unlike the first frame "
                                                 r".*level_a/frame_0000.npz' \(4 of 5 hold 'motion'\): every frame "
                                                 r"of a dataset holds the same optional arrays") as err:
        import_frames([root / "level_a", nomotion], data)
    assert err.value.name == "frames"
    assert sorted(p.name for p in (data / "samples").iterdir()) == before  # (nothing written, nothing lost)
    assert len(DatasetReader(data).ids) == 3
    # the other way round: the first frame lacks it, a later one holds it besides
    with pytest.raises(sdk.ParameterError, match=r"nomotion/frame_0000.npz' holds motion besides, unlike the first "
                                                 r"frame .*nomotion/frame_0001.npz'"):
        import_frames([nomotion / "frame_0001.npz", nomotion / "frame_0000.npz"], tmp_path / "data2", scene="x")
    assert not (tmp_path / "data2" / "samples").exists()


def test_convention_mistakes_are_warned_once_and_counted(dumps: Any, tmp_path: Path,
                                                         caplog: pytest.LogCaptureFixture) -> None:
    root, _, _ = dumps
    from rtp.cli._predict import _save_frame

    encoded = tmp_path / "encoded"  # normals still in their texture's encoding, n * 0.5 + 0.5
    encoded.mkdir()
    for f in sorted((root / "level_a").glob("*.npz")):
        arrays = dict(np.load(f))
        arrays["normal"] = arrays["normal"] * 0.5 + 0.5
        _save_frame(encoded / f.name, arrays)
    with caplog.at_level("WARNING", "rtp.capture"):
        report = import_frames(encoded, tmp_path / "data")
    assert report.written == 3 and list(report.warnings.values()) == [3]
    (record,) = [r for r in caplog.records if r.name == "rtp.capture" and r.levelname == "WARNING"]
    assert "frame_0000.npz: normal: " in record.getMessage() and "an encoded texture" in record.getMessage()
    # a convention that puts values out of range is refused, naming the file
    with pytest.raises(sdk.ParameterError, match=r"frame_0000.npz': depth: expected values in \[0, 1\]"):
        import_frames(root / "level_a", tmp_path / "data2", depth_kind="window")  # (it is linear depth)


@pytest.mark.slow
def test_the_command_imports_and_the_dataset_trains_and_evaluates(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    for level, scene in (("lvl_a", "procedural:0"), ("lvl_b", "procedural:3")):
        assert rtp_main(["import", f"dumps/{level}", "--write-example", "--frames", "4", "--size", f"{W}x{H}",
                         "--example-scene", scene]) == 0
    assert rtp_main(["import", "dumps/lvl_a", "dumps/lvl_b", "--out", "data"]) == 0
    out = capsys.readouterr().out
    assert "data: 8 frames imported, 0 already there" in out and "next: rtp targets data" in out
    assert rtp_main(["targets", "data", "--metrics", "jnyang"]) == 0
    assert TargetStore("data").load("lvl_a-frame_0000", "jnyang", 16).shape == (6, 4, 6)
    assert rtp_main(["train", "--data", "data", "--metric", "jnyang", "--out", "m.pt", "--steps", "20", "--batch", "4",
                     "--crop", "32", "--val-scenes", "lvl_b"]) == 0
    from rtp import export

    export.export_checkpoint("m.pt", "m.onnx")
    assert rtp_main(["evaluate", "m.onnx", "--data", "data", "--out", "ev"]) == 0
    (report,) = json.loads(Path("ev/evaluation.json").read_text())
    assert report["scene_roles"] == {"lvl_a": "train", "lvl_b": "validation"} and report["scenes"] == {"lvl_a": 4, "lvl_b": 4}


def test_fuzz_found_inputs_are_typed_errors_and_leave_no_manifest(dumps: Any, tmp_path: Path) -> None:
    """Two inputs the fuzz target of tests/test_fuzz_rooms.py found: a numpy integer tolerance reached the
    manifest's JSON (TypeError), and a 1-D final_1x1 its size (ValueError)."""
    root, _, _ = dumps
    with pytest.raises(sdk.ParameterError, match="tolerance"):
        import_frames(root / "level_a", tmp_path / "data", tolerance=np.int64(4881))
    assert not (tmp_path / "data" / "manifest.json").exists()  # (a later good import is not refused by it)
    assert import_frames(root / "level_a", tmp_path / "data", tolerance=np.float32(0.02)).written == 3
    frame = dict(np.load(root / "level_a" / "frame_0000.npz"))
    frame["final_1x1"] = np.zeros(9, np.int32)
    (tmp_path / "flat").mkdir()
    np.savez(tmp_path / "flat" / "frame_0000.npz", **frame)
    with pytest.raises(sdk.ParameterError, match=r"final_1x1 has shape \(9,\), expected \(H, W, 3\)"):
        import_frames(tmp_path / "flat", tmp_path / "data2")


def test_options_not_read_are_refused_not_ignored(dumps: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--frames N without --write-example imported every frame (not N), --out beside --write-example wrote no
    dataset: options taken and ignored are refused, naming them, before anything is written."""
    root, _, _ = dumps
    assert rtp_main(["import", str(root / "level_a"), "--out", str(tmp_path / "data"), "--frames", "2"]) == 2
    err = capsys.readouterr().err
    assert "--frames: an option of --write-example" in err and "Traceback" not in err, err
    assert not (tmp_path / "data").exists()
    assert rtp_main(["import", str(tmp_path / "ex"), "--write-example", "--frames", "1", "--size", f"{W}x{H}",
                     "--out", str(tmp_path / "data")]) == 2
    assert "--out: not read with --write-example" in capsys.readouterr().err
    assert not (tmp_path / "ex").exists() and not (tmp_path / "data").exists()


def test_a_tolerance_out_of_range_is_refused_naming_the_flag_not_a_frame(
        dumps: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp import DUMPS --out DATA --tolerance 5` was refused by the first frame's reprojection, its error naming
    that frame's file (`'dumps/level_a/frame_0000.npz': tolerance: ...`) as if the frame were wrong: the range is
    checked with the other arguments, said with the flag, before anything is read or written; the SDK's own limit,
    1, is taken."""
    from rtp.sdk._reproject import MAX_REPROJECTION_TOLERANCE

    root, _, _ = dumps
    for bad in ("5", "-0.1", "nan", str(MAX_REPROJECTION_TOLERANCE * 1.01)):
        assert rtp_main(["import", str(root / "level_a"), "--out", str(tmp_path / "data"), "--tolerance", bad]) == 2
        err = capsys.readouterr().err.strip().splitlines()[-1]
        assert err.startswith(f"rtp import: error: --tolerance: expected a number in [0, {MAX_REPROJECTION_TOLERANCE:g}]"), err
        assert "frame_0000" not in err
        with pytest.raises(sdk.ParameterError, match=r"^tolerance: expected a number in \[0, 1\]") as exc:
            import_frames(root / "level_a", tmp_path / "data", tolerance=float(bad))
        assert exc.value.name == "tolerance"
    assert not (tmp_path / "data").exists()
    assert import_frames(root / "level_a", tmp_path / "data", tolerance=MAX_REPROJECTION_TOLERANCE).written == 3


def test_each_kind_of_convention_warning_is_shown_by_the_command(dumps: Any, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Frames with two kinds of mistake (view matrices for row vectors, and so nothing reprojects) name both: every
    kind was logged with one template, "%s: %s", which the command's log collapsed into the first."""
    root, _, _ = dumps
    from rtp.cli._predict import _save_frame

    bad = tmp_path / "transposed"
    bad.mkdir()
    for f in sorted((root / "level_a").glob("*.npz")):
        arrays = dict(np.load(f))
        arrays["view"] = arrays["view"].T
        _save_frame(bad / f.name, arrays)
    assert rtp_main(["import", str(bad), "--out", str(tmp_path / "data")]) == 0
    err = capsys.readouterr().err
    assert "view: its last row is" in err and "seen: only" in err and "more like" not in err, err


def _damage(path: Path, member: str, at: float) -> None:
    """Flip 64 bytes of ``member``'s deflate stream in the frame file ``path``, ``at`` (0-1) of the way into it."""
    import zipfile

    with zipfile.ZipFile(path) as z:
        info = z.getinfo(member)
    data = bytearray(path.read_bytes())
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    off = start + 16 + int(at * (info.compress_size - 100))
    data[off:off + 64] = bytes(b ^ 0xFF for b in data[off:off + 64])
    path.write_bytes(bytes(data))


def test_a_damaged_frame_is_a_parameter_error_naming_it(dumps: Any, tmp_path: Path) -> None:
    # (zlib's raw "Error -3 while decompressing data" before: from the arrays' headers before anything was written,
    # or from a later frame's data midway through the import)
    import shutil

    root, _, _ = dumps
    level = tmp_path / "lvl"
    shutil.copytree(root / "level_a", level)
    good = (level / "frame_0001.npz").read_bytes()
    _damage(level / "frame_0001.npz", "depth.npy", 0.0)
    with pytest.raises(sdk.ParameterError, match=r"frame_0001.npz': not an .npz of arrays numpy can read \(error: "):
        import_frames(level, tmp_path / "data")
    assert not (tmp_path / "data" / "samples").exists() or not any((tmp_path / "data" / "samples").iterdir())
    (level / "frame_0001.npz").write_bytes(good)
    _damage(level / "frame_0001.npz", "final_1x1.npy", 0.2)  # (past what reading the headers decompresses)
    with pytest.raises(sdk.ParameterError, match=r"frame_0001.npz': a damaged .npz.*the same command imports the rest"):
        import_frames(level, tmp_path / "data")
    assert DatasetReader(tmp_path / "data").ids == ["lvl-frame_0000"]
    (level / "frame_0001.npz").write_bytes(good)
    assert (import_frames(level, tmp_path / "data").written, len(DatasetReader(tmp_path / "data"))) == (2, 3)


def test_a_linked_folder_is_the_level_of_its_name_and_a_damaged_sample_is_imported_again(
        dumps: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    root, _, _ = dumps
    (tmp_path / "arena").symlink_to(root / "level_a")  # (the level "level_a" before: the link's target's name)
    data = tmp_path / "data"
    assert import_frames(tmp_path / "arena", data).written == 3
    assert DatasetReader(data).ids == [f"arena-frame_{i:04d}" for i in range(3)]
    assert {DatasetReader(data)[i].meta["scene"] for i in DatasetReader(data).ids} == {"arena"}
    # a sample cut short since (a copy, a disk): imported again with a warning, not skipped for rtp targets to fail on
    sample = data / "samples" / "arena-frame_0001.npz"
    sample.write_bytes(sample.read_bytes()[:1000])
    with caplog.at_level("WARNING", logger="rtp.capture"):
        report = import_frames(tmp_path / "arena", data)
    assert (report.written, report.skipped) == (1, 2)
    assert any("arena-frame_0001.npz: unreadable sample" in r.getMessage() and "imported again" in r.getMessage()
               for r in caplog.records)
    assert DatasetReader(data)["arena-frame_0001"].final("1x1").shape == (H, W, 3)


def test_a_frame_dumped_again_is_imported_again_and_an_unchanged_copy_is_not(
        dumps: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]) -> None:
    """An import resumed by sample id alone kept the samples of frames the engine had dumped again since (a fix to
    its G-buffers: `rtp import` said "0 frames imported, 3 already there" and trained on the old ones). Each sample
    records its frame file; a frame with other bytes is imported again, replacing its sample (whose targets are then
    stale), and a copy of the same bytes (another time) is still skipped."""
    import os
    import shutil

    root, _, _ = dumps
    level = tmp_path / "level_a"
    shutil.copytree(root / "level_a", level)
    data = tmp_path / "data"
    assert import_frames(level, data).written == 3
    from rtp.capture import compute_targets

    compute_targets(data, ["psnr"])
    store = TargetStore(data)
    assert all(store.has(i, "psnr") for i in DatasetReader(data).ids)
    # frame 1 dumped again (another frame's bytes); frame 2 copied anew, the same bytes at another time
    shutil.copyfile(root / "level_b" / "frame_0001.npz", level / "frame_0001.npz")
    os.utime(level / "frame_0002.npz", ns=(1_000_000_000, 1_000_000_000))
    with caplog.at_level("WARNING", logger="rtp.capture"):
        report = import_frames(level, data)
    assert (report.written, report.replaced, report.skipped) == (1, 1, 2)
    assert any("frame_0001.npz changed since it was imported as sample level_a-frame_0001" in r.getMessage()
               for r in caplog.records)
    fresh = import_frames(root / "level_b" / "frame_0001.npz", tmp_path / "fresh", scene="level_a")
    assert fresh.written == 1
    got, want = DatasetReader(data)["level_a-frame_0001"], DatasetReader(tmp_path / "fresh")["level_a-frame_0001"]
    np.testing.assert_array_equal(got.final("1x1"), want.final("1x1"))
    assert not store.has("level_a-frame_0001", "psnr") and store.has("level_a-frame_0000", "psnr")
    # the command says so
    shutil.copyfile(root / "level_a" / "frame_0001.npz", level / "frame_0001.npz")
    assert rtp_main(["import", str(level), "--out", str(data)]) == 0
    assert "1 frames imported (1 of them dumped again since their import: their samples replaced), 2 already there" \
        in capsys.readouterr().out


def test_exchanged_anisotropic_rate_images_are_warned_once_and_counted(
        dumps: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture, capsys: pytest.CaptureFixture[str]) -> None:
    """final_1x2 and final_2x1 exchanged in an engine's dump (its names for the rates the other way round) imported
    without a word, and trained a model that picks 2x1 where 1x2 would do: the images' own blocks show it."""
    root, _, _ = dumps
    from rtp.capture._import import _exchanged
    from rtp.cli._predict import _save_frame

    report = import_frames([root / "level_a", root / "level_b"], tmp_path / "true")
    assert (report.written, report.exchanged) == (6, 0)
    for pair in (("1x2", "2x1"), ("2x4", "4x2")):
        swapped = tmp_path / f"swapped_{pair[0]}"
        swapped.mkdir()
        for f in sorted((root / "level_a").glob("*.npz")):
            arrays = dict(np.load(f))
            a, b = (f"final_{r}" for r in pair)
            arrays[a], arrays[b] = arrays[b], arrays[a]
            _save_frame(swapped / f.name, arrays)
        caplog.clear()
        with caplog.at_level("WARNING", "rtp.capture"):
            report = import_frames(swapped, tmp_path / f"data_{pair[0]}", scene="x")
        assert (report.written, report.exchanged, report.warnings) == (3, 3, {})
        (record,) = [r for r in caplog.records if r.name == "rtp.capture" and r.levelname == "WARNING"]
        assert f"swapped_{pair[0]}/frame_0000.npz: final_{pair[0]} and final_{pair[1]} look exchanged" \
            in record.getMessage()
    assert rtp_main(["import", str(tmp_path / "swapped_1x2"), "--out", str(tmp_path / "cli")]) == 0
    assert "rate images look exchanged on 3 of 3 frames" in capsys.readouterr().err
    # the renderer's own rate images at sizes whose blocks start at another phase (odd sizes, GL's rows from the
    # bottom) and in other scenes: nothing said
    from rtp.capture import load_scene
    from rtp.capture.paths import camera_path
    from rtp.plugins.moderngl import Renderer

    for scene, (w, h) in (("procedural:7", (75, 47)), ("procedural:5", (130, 66)), ("procedural:2", (33, 17))):
        scn, blockers = load_scene(scene, None, None, None)
        cams = camera_path(scn, 3, "fast", 0, blockers=blockers).cameras
        with Renderer(w, h) as r:
            r.load_scene(scn)
            prev = r.render(cams[0])
            for cam in cams[1:]:
                cur = r.render(cam, prev)
                finals = {f"final_{k}": np.round(v * 255) / 255 for k, v in cur.colour.items()}
                assert _exchanged(finals) == [], scene
                swapped = {**finals, "final_1x2": finals["final_2x1"], "final_2x1": finals["final_1x2"],
                           "final_2x4": finals["final_4x2"], "final_4x2": finals["final_2x4"]}
                assert _exchanged(swapped) == [("2x1", "1x2"), ("4x2", "2x4")], scene
                prev = cur


def test_a_later_frames_g_buffer_of_another_size_is_refused_before_anything_is_written(
        dumps: Any, tmp_path: Path) -> None:
    """Only the final images and the depth were checked against the frame's size before the import began: a later
    frame's albedo of another size was found at its turn, the frames before it written (the docs: "before the first
    sample is written, every frame is checked: ... its size")."""
    import shutil

    root, _, _ = dumps
    from rtp.cli._predict import _save_frame

    for key, cut in (("albedo", lambda a: a[:-2]), ("motion", lambda a: a[:, 1:]),
                     ("prev_colour", lambda a: a[::2, ::2])):
        level = tmp_path / f"lvl_{key}"
        shutil.copytree(root / "level_a", level)
        arrays = dict(np.load(level / "frame_0002.npz"))
        arrays[key] = cut(arrays[key])
        _save_frame(level / "frame_0002.npz", arrays)
        with pytest.raises(sdk.ParameterError, match=rf"frame_0002.npz': {key} has shape \(") as err:
            import_frames(level, tmp_path / f"data_{key}")
        assert err.value.name == key
        assert not (tmp_path / f"data_{key}").exists()


def test_frames_past_the_machines_memory_are_refused_before_any_is_read(
        dumps: Any, tmp_path: Path, machine_memory: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """An import sized nothing: frames past the machine's memory were read until the system killed it, or numpy's
    MemoryError was reported as a damaged frame file."""
    root, _, _ = dumps
    from rtp.capture import _import

    read: list[Any] = []
    real = _import.read_frame
    monkeypatch.setattr(_import, "read_frame", lambda *a, **k: read.append(a) or real(*a, **k))
    machine_memory(MemTotal=32 * 2**20)
    with pytest.raises(sdk.ParameterError, match=r"frames: an import of frames of 96x64 holds about 0.1 GiB, more "
                                                 r"than this machine's 0.0 GiB of memory: smaller frames") as err:
        import_frames(root / "level_a", tmp_path / "data")
    assert err.value.name == "frames" and not read and not (tmp_path / "data").exists()
    machine_memory(MemTotal=4 * 2**30)  # (a 96x64 frame's import: about 67 MiB)
    assert import_frames(root / "level_a", tmp_path / "data").written == 3


def test_another_folders_frames_of_the_same_names_and_scene_do_not_replace_its_samples(
        dumps: Any, tmp_path: Path) -> None:
    """Two dump sessions of one level (each frame_0000.npz ...) imported one after the other with the same --scene:
    the second's frames were taken for the first's dumped again, replacing its samples ("3 frames imported (3 of them
    dumped again since their import: their samples replaced)"), the first session lost from the dataset."""
    import shutil

    root, _, _ = dumps
    data = tmp_path / "data"
    assert import_frames(root / "level_a", data, scene="arena").written == 3
    before = {p.name: p.read_bytes() for p in (data / "samples").iterdir()}
    with pytest.raises(sdk.ParameterError, match=r"level_b/frame_0000.npz' would replace the sample 'arena-frame_0000'"
                                                 r", imported from '.*level_a/frame_0000.npz', another frame file, "
                                                 r"still there as imported") as err:
        import_frames(root / "level_b", data, scene="arena")
    assert err.value.name == "frames"
    assert {p.name: p.read_bytes() for p in (data / "samples").iterdir()} == before
    # the first folder moved away (or dumped again in place): its frames' new bytes replace the samples, as before
    moved = tmp_path / "session2"
    shutil.copytree(root / "level_b", moved)
    shutil.copytree(root / "level_a", tmp_path / "session1")
    again = tmp_path / "again"
    assert import_frames(tmp_path / "session1", again, scene="arena").written == 3
    shutil.rmtree(tmp_path / "session1")
    report = import_frames(moved, again, scene="arena")
    assert (report.written, report.replaced) == (3, 3)


def test_a_pickled_array_is_named_before_anything_is_written_and_an_engines_own_is_not_read(
        dumps: Any, tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A later frame's G-buffer saved as a pickled object array was found at its turn, after the frames before it
    were written, and called "a damaged .npz"; an engine's own metadata beside the arrays (``meta={...}``, pickled)
    refused every frame."""
    root, _, _ = dumps
    level = tmp_path / "lvl"
    level.mkdir()
    for f in sorted((root / "level_a").glob("*.npz")):
        np.savez(level / f.name, **dict(np.load(f)), meta={"engine": "mine", "frame": f.stem})
    with caplog.at_level("WARNING"):
        assert import_frames(level, tmp_path / "data").written == 3
    assert "array 'meta' is not a G-buffer and is not read" in caplog.text
    arrays = dict(np.load(root / "level_a" / "frame_0002.npz"))
    np.savez(level / "frame_0002.npz", **{**arrays, "prev_depth": arrays["prev_depth"].astype(object)})
    with pytest.raises(sdk.ParameterError, match=r"frame_0002.npz': prev_depth is a pickled object array") as err:
        import_frames(level, tmp_path / "data2")
    assert err.value.name == "prev_depth"
    assert not (tmp_path / "data2" / "samples").exists() or not any((tmp_path / "data2" / "samples").iterdir())


def test_motion_vectors_with_y_up_are_warned_once_and_counted(dumps: Any, tmp_path: Path,
                                                              caplog: pytest.LogCaptureFixture) -> None:
    """Motion vectors with y up (OpenGL's, Unity's) were imported without a word, and the samples' motion planes and
    reprojection were wrong: the kind is named once and counted on every frame, with the conversion."""
    root, _, _ = dumps
    flipped = tmp_path / "flipped"
    flipped.mkdir()
    for f in sorted((root / "level_a").glob("*.npz")):
        arrays = dict(np.load(f))
        np.savez(flipped / f.name, **{**arrays, "motion": arrays["motion"] * np.float32([1, -1])})
    with caplog.at_level("WARNING", "rtp.capture"):
        report = import_frames(flipped, tmp_path / "data")
    (kind,) = [k for k in report.warnings if k.startswith("motion: ")]
    assert report.warnings[kind] == 3 and "y up" in kind
    assert "multiply these by (1, -1)" in caplog.text


def test_colour_in_linear_light_is_warned_once_and_counted(dumps: Any, tmp_path: Path,
                                                           caplog: pytest.LogCaptureFixture) -> None:
    """prev_colour dumped in linear light (an HDR or linear target read back before its sRGB conversion) imported
    without a word, and every sample's reprojected planes were darker than the frame shown: the reprojection against
    final_1x1 names it, and final images in linear light beside an sRGB prev_colour; colour all in linear light
    agrees with itself and is not named (docs/dataset.md)."""
    root, _, _ = dumps
    from rtp.capture._import import _linear_light

    def linear(x: np.ndarray) -> np.ndarray:
        return np.asarray(sdk.srgb_to_linear(x), np.float32)

    mistakes = {"prev": lambda a: {"prev_colour": linear(a["prev_colour"])},
                "finals": lambda a: {k: linear(a[k]) for k in a if k.startswith("final_")},
                "all": lambda a: {k: linear(a[k]) for k in a if k.startswith("final_") or k == "prev_colour"}}
    for name, change in mistakes.items():
        folder = tmp_path / name
        folder.mkdir()
        for f in sorted((root / "level_a").glob("*.npz")):
            arrays = dict(np.load(f))
            np.savez(folder / f.name, **{**arrays, **change(arrays)})
        caplog.clear()
        with caplog.at_level("WARNING", "rtp.capture"):
            report = import_frames(folder, tmp_path / f"data_{name}", scene="x")
        assert report.written == 3
        if name == "all":
            assert report.warnings == {}, report.warnings
            continue
        (kind,) = report.warnings
        assert report.warnings[kind] == 3
        key = "prev_colour" if name == "prev" else "final_1x1"
        assert kind.startswith(f"{key.replace('1x1', '#x#')}: looks like linear light"), kind  # (numbers as #)
        (record,) = [r for r in caplog.records if r.name == "rtp.capture" and r.levelname == "WARNING"]
        assert f"{name}/frame_0000.npz: {key}: looks like linear light" in record.getMessage()
        assert "display-encoded, as shown (tone-mapped, sRGB)" in record.getMessage()
        assert "sdk.linear_to_srgb" in record.getMessage()
    # too few surfaces seen in both frames (a camera cut, a sky): nothing said
    rep = np.full((8, 8, 3), 0.2, np.float32)
    geo = np.ones((8, 8), bool)
    assert _linear_light(rep, np.ones((8, 8), np.float32), np.asarray(sdk.linear_to_srgb(rep), np.float32), geo) \
        is not None
    assert _linear_light(rep, np.zeros((8, 8), np.float32), np.asarray(sdk.linear_to_srgb(rep), np.float32), geo) \
        is None


def test_write_example_reads_a_map_from_the_cache_dir_given(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """`rtp import --write-example --example-scene MAP` read only the default scene cache: it had no --cache-dir,
    which every other command that reads maps takes ("unrecognized arguments"). It takes it now, as one of
    --write-example's options (refused without it, as the others are), and reads the map from there."""
    default, given = tmp_path / "default-cache", tmp_path / "my cache"
    monkeypatch.setenv("RTP_SCENE_CACHE", str(default))
    monkeypatch.chdir(tmp_path)
    argv = ["import", "frames", "--write-example", "--frames", "2", "--size", "64x48", "--example-scene", "oa_dm1"]
    assert rtp_main([*argv, "--cache-dir", str(given)]) == 2
    err = capsys.readouterr().err
    assert f"no scene index at {given / 'index.json'}" in err and str(default) not in err, err
    assert rtp_main(argv) == 2  # (without it: the default cache, $RTP_SCENE_CACHE)
    assert f"no scene index at {default / 'index.json'}" in capsys.readouterr().err
    assert rtp_main(["import", "frames", "--out", "data", "--cache-dir", str(given)]) == 2
    assert "--cache-dir: an option of --write-example" in capsys.readouterr().err
    assert not (tmp_path / "frames").exists() and not (tmp_path / "data").exists()
