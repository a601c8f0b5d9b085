"""The dataset format: atomic per-sample writes, resumable writers, readers for both layouts."""

from __future__ import annotations

import json
import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.capture._dataset import (
    BUFFERS,
    FORMAT,
    FORMAT_VERSION,
    DatasetError,
    DatasetReader,
    DatasetWriter,
    PaperDatasetReader,
    open_dataset,
    write_png,
)


def _buffers(h: int = 24, w: int = 40, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    out: dict[str, np.ndarray] = {}
    for name, spec in BUFFERS.items():
        n = len(spec.channels) or 3
        shape = (h, w, n) if n > 1 else (h, w)
        a = rng.random(shape, dtype=np.float32)
        if name == "normal":
            a = a * 2 - 1
        if name in ("depth", "motion"):
            a = a * 30
        out[name] = a
    return out


def test_round_trip_with_stated_precision(tmp_path: Path) -> None:
    w = DatasetWriter(tmp_path / "ds", settings={"size": [40, 24]})
    bufs = _buffers()
    w.write("s000001", bufs, {"scene": "oa_dm1", "profile": "slow"})
    w.finalize()
    r = DatasetReader(tmp_path / "ds")
    assert r.ids == ["s000001"] and len(r) == 1
    s = r["s000001"]
    assert s.meta == {"scene": "oa_dm1", "profile": "slow"} and s.size == (24, 40)
    np.testing.assert_allclose(s.buffer("albedo"), bufs["albedo"], atol=1 / 510 + 1e-7)
    np.testing.assert_allclose(s.buffer("normal"), bufs["normal"], atol=1e-3)
    np.testing.assert_allclose(s.channel("depth"), bufs["depth"], rtol=1e-3)
    x = s.inputs(sdk.DEFAULT_INPUTS)
    assert x.shape == (4, 24, 40) and x.dtype == np.float32
    np.testing.assert_allclose(x[3], bufs["normal"][..., 2], atol=1e-3)
    np.testing.assert_allclose(s.final("2x4"), bufs["final_2x4"], atol=1 / 510 + 1e-7)
    assert r.select(scene="oa_dm1") == ["s000001"] and r.select(scene="kaos") == []
    assert r.manifest["bytes_per_sample"] > 0


def test_every_sdk_channel_is_stored_or_derived(tmp_path: Path) -> None:
    stored = {c for spec in BUFFERS.values() for c in spec.channels}
    derived = {"depth.edge", "reprojected.y", "albedo.y", "reprojected.y.dx", "reprojected.y.dy", "reprojected.y.blocks",
               "albedo.y.blocks", "reprojected.y.tiles", "albedo.y.tiles"}
    assert stored | derived == set(sdk.CHANNELS)
    w = DatasetWriter(tmp_path / "ds")
    bufs = _buffers()
    w.write("s0", bufs, {"scene": "a"})
    s = DatasetReader(tmp_path / "ds")["s0"]
    # derived when read, by the SDK's definition, from the stored (float16) depth
    np.testing.assert_array_equal(s.channel("depth.edge"), sdk.depth_edges(s.buffer("depth")))
    assert s.inputs(("seen", "depth.edge")).shape == (2, 24, 40)
    # the luma planes, likewise, from the stored (8-bit) colour
    np.testing.assert_array_equal(s.channel("reprojected.y"), sdk.luma(s.buffer("reprojected")))
    np.testing.assert_array_equal(s.channel("albedo.y"), sdk.luma(s.buffer("albedo")))
    dx, dy = sdk.pixel_differences(sdk.luma(s.buffer("reprojected")))
    np.testing.assert_array_equal(s.channel("reprojected.y.dx"), dx)
    np.testing.assert_array_equal(s.channel("reprojected.y.dy"), dy)
    np.testing.assert_array_equal(s.channel("albedo.y.blocks"), sdk.block_variances(sdk.luma(s.buffer("albedo"))))
    np.testing.assert_array_equal(s.channel("reprojected.y.tiles"), sdk.tile_variances(sdk.luma(s.buffer("reprojected"))))


def test_writer_validates(tmp_path: Path) -> None:
    w = DatasetWriter(tmp_path / "ds")
    bufs = _buffers()
    with pytest.raises(DatasetError, match="missing buffers"):
        w.write("a", {k: v for k, v in bufs.items() if k != "depth"}, {})
    with pytest.raises(sdk.InputShapeError, match="albedo"):
        w.write("a", {**bufs, "albedo": bufs["albedo"][:10]}, {})
    nan = bufs["depth"].copy()
    nan[0, 0] = np.nan
    with pytest.raises(DatasetError, match="NaN"):
        w.write("a", {**bufs, "depth": nan}, {})
    with pytest.raises(DatasetError, match="sample id"):
        w.write("../evil", bufs, {})
    # an int64 image of 0-255 was stored as all 1.0; an empty buffer was written and refused on reading
    with pytest.raises(sdk.InputDtypeError, match="final_1x1"):
        w.write("a", {**bufs, "final_1x1": (bufs["final_1x1"] * 255).astype(np.int64)}, {})
    with pytest.raises(sdk.InputShapeError, match="empty"):
        w.write("a", {k: v[:0] for k, v in bufs.items()}, {})
    assert not list((tmp_path / "ds" / "samples").iterdir())
    w.write("a", bufs, {})
    for key in ("format", "samples", "settings"):  # ("format": "mine" left a folder no reader opens)
        with pytest.raises(DatasetError, match="the manifest's own keys"):
            w.finalize({key: "mine"})
    w.finalize({"note": "kept"})
    assert DatasetReader(tmp_path / "ds").manifest["note"] == "kept"


def test_the_target_store_keeps_to_its_folder(tmp_path: Path) -> None:
    """A metric name such as "../samples" wrote targets over the captured sample."""
    from rtp.capture import TargetError, TargetStore

    w = DatasetWriter(tmp_path / "ds")
    w.write("a", _buffers(), {})
    before = (tmp_path / "ds" / "samples" / "a.npz").read_bytes()
    store = TargetStore(tmp_path / "ds")
    for metric, sample in (("../samples", "a"), ("nope", "a"), ("jnyang", "../a")):
        with pytest.raises((TargetError, DatasetError)):
            store.write(sample, metric, np.zeros((6, 2, 3), np.float32), (24, 40))
    with pytest.raises(TargetError, match="unknown metric"):
        store.declare("nope", {})
    assert (tmp_path / "ds" / "samples" / "a.npz").read_bytes() == before


def test_truncated_targets_are_computed_again_and_killed_jobs_leave_no_temporary_files(tmp_path: Path) -> None:
    """`rtp targets` counted a truncated target file as done (training then failed on it), and the temporary
    files of a killed targets job or manifest write stayed behind for good."""
    from rtp.capture import TargetStore, compute_targets

    w = DatasetWriter(tmp_path / "ds")
    for i in range(2):
        w.write(f"s{i}", _buffers(seed=i), {"scene": "a"})
    w.finalize()
    assert compute_targets(tmp_path / "ds", ["psnr"]) == 2
    store = TargetStore(tmp_path / "ds")
    cut = store.path("s1", "psnr")
    cut.write_bytes(cut.read_bytes()[:100])
    left = [cut.parent / ".s0.npz.a8a6pmk6.tmp", tmp_path / "ds" / ".manifest.json.xyz.tmp"]
    for tmp in left:
        tmp.write_bytes(b"half")
    assert not store.has("s1", "psnr") and store.has("s0", "psnr")
    targets_manifest_tmp = store.root / ".manifest.json.k1ll3d.tmp"  # (a targets job killed in its manifest's write)
    targets_manifest_tmp.write_bytes(b"half")
    assert compute_targets(tmp_path / "ds", ["psnr"]) == 1
    assert store.load("s1", "psnr", 16).shape == (6, 2, 3)
    assert not targets_manifest_tmp.exists()  # (left for good before: only the metrics' folders were cleared)
    DatasetWriter(tmp_path / "ds").remove_stale()  # (what a capture's start runs)
    assert not any(tmp.exists() for tmp in left)


def test_targets_whose_manifest_is_lost_are_not_mixed_with_new_parameters(tmp_path: Path) -> None:
    """With targets/manifest.json lost, a targets run with another --weber-l recorded it and kept the old files:
    one metric's targets of two parameter sets, trained on as one."""
    from rtp.capture import TargetError, TargetStore, compute_targets

    w = DatasetWriter(tmp_path / "ds")
    for i in range(2):
        w.write(f"s{i}", _buffers(seed=i), {"scene": "a"})
    w.finalize()
    assert compute_targets(tmp_path / "ds", ["jnyang", "psnr"]) == 2
    manifest = tmp_path / "ds" / "targets" / "manifest.json"
    kept = manifest.read_text()
    manifest.unlink()
    folder = tmp_path / "ds" / "targets" / "jnyang"
    with pytest.raises(TargetError, match=re.escape(f"{folder} holds jnyang targets, but {manifest} is missing: the "
                                                    f"parameters they were computed with are unknown")):
        compute_targets(tmp_path / "ds", ["jnyang"], weber_l=0.5)
    manifest.write_text(kept.replace('"jnyang"', '"other"'))  # (written over without jnyang: the same)
    with pytest.raises(TargetError, match=f"but {re.escape(str(manifest))} does not record jnyang: .*restore the "
                                          f"manifest, or delete {re.escape(str(folder))} to compute jnyang's"):
        TargetStore(tmp_path / "ds").declare("jnyang", {"weber_l": 0.5})
    manifest.write_text(kept)  # restored: the same parameters resume, other ones are refused as before
    assert compute_targets(tmp_path / "ds", ["jnyang"]) == 0
    import shutil

    shutil.rmtree(folder)  # (the hint: the metric's own folder; psnr's targets stay)
    manifest.unlink()
    assert compute_targets(tmp_path / "ds", ["jnyang"], weber_l=0.5) == 2
    assert TargetStore(tmp_path / "ds").metrics == {"jnyang": {"weber_l": 0.5}}


def test_a_targets_job_keeps_the_metrics_a_job_that_ended_as_it_started_declared(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The targets manifest was read before the job took its writer lock: a job that held the lock until then
    and declared a metric meanwhile (yang) had it written over by this one's declare of its own (psnr), yang's
    files kept and its parameters lost, so every later `rtp targets --metrics yang` refused them."""
    import contextlib

    from rtp.capture import TargetStore, _targets, compute_targets

    w = DatasetWriter(tmp_path / "ds")
    w.write("s0", _buffers(), {"scene": "a"})
    w.finalize()
    lock = _targets.writer_lock

    @contextlib.contextmanager
    def after_another_job(*args: Any, **kwargs: Any) -> Any:
        # (the other job, which held the lock while this one read the manifest, ends now)
        other = TargetStore(tmp_path / "ds")
        other.declare("yang", {})
        other.write("s0", "yang", np.ones((6, 6, 10), np.float32), (24, 40))
        with lock(*args, **kwargs):
            yield

    monkeypatch.setattr(_targets, "writer_lock", after_another_job)
    assert compute_targets(tmp_path / "ds", ["psnr"]) == 1
    monkeypatch.setattr(_targets, "writer_lock", lock)
    assert TargetStore(tmp_path / "ds").metrics == {"psnr": {}, "yang": {}}
    assert compute_targets(tmp_path / "ds", ["yang", "psnr"]) == 0  # (refused before: yang not in the manifest)


def test_a_sample_captured_again_while_its_targets_are_computed_leaves_them_stale(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Staleness is the sample file being newer than its targets' file. A sample written again (a capture or an
    import into the folder, which another lock guards) after `rtp targets` read it and before it wrote its
    targets left targets of the old sample newer than the new one: kept as up to date, and trained on."""
    from rtp.capture import TargetError, TargetStore, _targets, compute_targets

    w = DatasetWriter(tmp_path / "ds")
    w.write("s0", _buffers(seed=0), {"scene": "a"})
    w.finalize()
    sample = tmp_path / "ds" / "samples" / "s0.npz"
    past = sample.stat().st_mtime_ns - 10**10
    os.utime(sample, ns=(past, past))  # (captured a while ago)
    real = _targets.sample_targets

    def recaptured_meanwhile(*args: Any, **kwargs: Any) -> Any:
        out = real(*args, **kwargs)
        DatasetWriter(tmp_path / "ds").write("s0", _buffers(seed=1), {"scene": "a"})  # (the new sample)
        return out

    monkeypatch.setattr(_targets, "sample_targets", recaptured_meanwhile)
    assert compute_targets(tmp_path / "ds", ["psnr"]) == 1
    store = TargetStore(tmp_path / "ds")
    assert store.stale("s0", "psnr") and not store.has("s0", "psnr")
    monkeypatch.setattr(_targets, "sample_targets", real)
    assert compute_targets(tmp_path / "ds", ["psnr"]) == 1  # (computed again, of the sample there now)
    assert store.has("s0", "psnr") and compute_targets(tmp_path / "ds", ["psnr"]) == 0
    with pytest.raises(TargetError, match="sample_mtime_ns: expected an integer"):
        store.write("s0", "psnr", np.ones((6, 6, 10), np.float32), (24, 40), sample_mtime_ns=1.5)  # type: ignore[arg-type]


def test_targets_stay_fresh_when_the_dataset_is_copied_and_a_sample_written_again_is_still_caught(
        tmp_path: Path) -> None:
    """Staleness was the sample file being newer than its targets' file. A copy gives files new times in its own
    order (`cp -r` or `rsync -r` without -p/-t, a checkout): targets copied before their samples were all stale (the
    next `rtp targets` recomputed everything, `rtp evaluate` refused), and a sample captured again whose copy came
    before its old targets' looked up to date (those of the old sample trained on). A target file records its
    sample's fingerprint, and that decides, whatever the times."""
    import shutil

    from rtp.capture import TargetError, TargetStore, compute_targets

    src, dst = tmp_path / "ds", tmp_path / "copy"
    w = DatasetWriter(src)
    for i in range(2):
        w.write(f"s{i}", _buffers(seed=i), {"scene": "a"})
    w.finalize()
    assert compute_targets(src, ["psnr"]) == 2
    shutil.copytree(src, dst)
    later = 2_000_000_000 * 10**9  # (the copy's targets written first, its samples after: as `cp -r` may)
    for f in (dst / "targets").rglob("*"):
        os.utime(f, ns=(later, later))
    for f in (dst / "samples").glob("*.npz"):
        os.utime(f, ns=(later + 10**9, later + 10**9))
    store = TargetStore(dst)
    assert not store.stale("s0", "psnr") and store.has("s1", "psnr")
    assert store.load("s0", "psnr", 8).shape == (6, 3, 5)
    assert compute_targets(dst, ["psnr"]) == 0  # (nothing recomputed)
    # s0 captured again (other content), then copied before its targets: its file older than theirs
    DatasetWriter(dst).write("s0", _buffers(seed=5), {"scene": "a"})
    os.utime(dst / "samples" / "s0.npz", ns=(later - 10**9, later - 10**9))
    assert store.stale("s0", "psnr") and not store.has("s0", "psnr") and not store.stale("s1", "psnr")
    with pytest.raises(TargetError, match="out of date"):
        store.load("s0", "psnr", 8)
    assert compute_targets(dst, ["psnr"]) == 1
    assert store.has("s0", "psnr")


def test_targets_without_a_sample_fingerprint_are_judged_by_their_times(tmp_path: Path) -> None:
    """Target files of an rtp before fingerprints (every dataset computed so far) keep the rule they were written
    under: fresh unless the sample file is newer, so none is recomputed by the upgrade; so does a file written with
    only ``sample_mtime_ns``. A fingerprint that is not a string is refused."""
    from rtp.capture import TargetError, TargetStore

    w = DatasetWriter(tmp_path / "ds")
    w.write("s0", _buffers(), {"scene": "a"})
    w.finalize()
    sample = tmp_path / "ds" / "samples" / "s0.npz"
    store = TargetStore(tmp_path / "ds")
    store.declare("psnr", {})
    store.write("s0", "psnr", np.ones((6, 6, 10), np.float32), (24, 40), sample_mtime_ns=sample.stat().st_mtime_ns)
    with np.load(store.path("s0", "psnr")) as z:
        assert sorted(z.files) == ["size", "values"]  # (the layout of the files written before)
    assert store.has("s0", "psnr")
    t = store.path("s0", "psnr").stat().st_mtime_ns + 10**9
    os.utime(sample, ns=(t, t))
    assert store.stale("s0", "psnr")
    store.write("s0", "psnr", np.ones((6, 6, 10), np.float32), (24, 40))  # (records the sample there now)
    os.utime(sample, ns=(t + 10**9, t + 10**9))
    assert store.has("s0", "psnr")
    with pytest.raises(TargetError, match="fingerprint: expected"):
        store.write("s0", "psnr", np.ones((6, 6, 10), np.float32), (24, 40), fingerprint=b"x")  # type: ignore[arg-type]


@pytest.mark.parametrize("corrupt", ["manifest", "manifest-json", "manifest-base", "npz", "npz-shape"])
def test_corrupt_targets_are_target_errors(tmp_path: Path, corrupt: str) -> None:
    """A damaged targets manifest or file leaked JSONDecodeError / BadZipFile out of evaluate()."""
    from rtp.capture import TargetError, TargetStore

    DatasetWriter(tmp_path / "ds").write("a", _buffers(), {})
    store = TargetStore(tmp_path / "ds")
    store.declare("jnyang", {"weber_l": 0.02})
    store.write("a", "jnyang", np.ones((6, 6, 10), np.float32), (24, 40))
    assert store.load("a", "jnyang", 16).shape == (6, 2, 3)
    manifest, npz = tmp_path / "ds" / "targets" / "manifest.json", store.path("a", "jnyang")
    if corrupt == "manifest":
        manifest.write_bytes(b"\x00\xff{")
    elif corrupt == "manifest-json":
        manifest.write_text("[1, 2]")
    elif corrupt == "manifest-base":
        manifest.write_text('{"format": "rtp-targets", "format_version": 1, "base_tile": "4"}')
    elif corrupt == "npz":
        npz.write_bytes(npz.read_bytes()[:40])
    else:
        with open(npz, "wb") as f:
            np.savez(f, values=np.ones((6, 3, 3), np.float32), size=np.array([24, 40]))
    with pytest.raises(TargetError, match=r"manifest\.json|a\.npz"):
        TargetStore(tmp_path / "ds").load("a", "jnyang", 16)


def test_targets_that_are_not_finite_are_refused_on_write_and_on_load(tmp_path: Path) -> None:
    """A NaN target was written and loaded in silence, and trained on."""
    from rtp.capture import TargetError, TargetStore

    DatasetWriter(tmp_path / "ds").write("a", _buffers(), {})
    store = TargetStore(tmp_path / "ds")
    store.declare("jnyang", {"weber_l": 0.02})
    values = np.ones((6, 6, 10), np.float32)
    for bad in (np.nan, np.inf):
        v = values.copy()
        v[2, 3, 4] = bad
        with pytest.raises(TargetError, match=r"jnyang targets of sample 'a': 1 of 360 values are NaN or infinite"):
            store.write("a", "jnyang", v, (24, 40))
        assert not store.path("a", "jnyang").exists()
    path = store.path("a", "jnyang")  # (one an older rtp wrote, or damaged since)
    path.parent.mkdir(parents=True)
    with open(path, "wb") as f:
        np.savez(f, values=v, size=np.array([24, 40]))
    with pytest.raises(TargetError, match=re.escape(f"{path}: 1 of 360 targets are NaN or infinite; delete the file "
                                                    f"and run `rtp targets {tmp_path / 'ds'}` again")):
        store.load("a", "jnyang", 16)


def test_negative_stored_mse_is_refused_on_write_and_on_load(tmp_path: Path) -> None:
    """PSNR is stored as the tile MSE: a negative one was written in silence and read back as a NaN PSNR (then an
    InputError of sdk.psnr_from_mse naming no file). Other metrics' negative values are theirs to judge."""
    from rtp.capture import TargetError, TargetStore

    DatasetWriter(tmp_path / "ds").write("a", _buffers(), {})
    store = TargetStore(tmp_path / "ds")
    store.declare("psnr", {})
    store.declare("jnyang", {"weber_l": 0.02})
    v = np.full((6, 6, 10), 1e-3, np.float32)
    v[1, 2, 3] = -0.5
    with pytest.raises(TargetError, match=r"psnr targets of sample 'a': expected the tile mean squared errors "
                                          r"\(>= 0.*got 1 negative, down to -0.5.*nothing is written"):
        store.write("a", "psnr", v, (24, 40))
    assert not store.path("a", "psnr").exists()
    store.write("a", "jnyang", v, (24, 40))  # (not an MSE)
    assert store.load("a", "jnyang", 4).min() == np.float32(-0.5)
    path = store.path("a", "psnr")  # (one an older rtp wrote)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        np.savez(f, values=v, size=np.array([24, 40]))
    with pytest.raises(TargetError, match=re.escape(f"{path}: 1 of 360 stored mean squared errors are negative; "
                                                    f"delete the file and run `rtp targets {tmp_path / 'ds'}` again")):
        store.load("a", "psnr", 16)


def test_targets_at_a_tile_past_the_frame_pool_without_padding(tmp_path: Path) -> None:
    """A tile far larger than the frame padded the base tiles to its size (tile**2 / 16 floats)."""
    from rtp.capture import TargetError, TargetStore

    DatasetWriter(tmp_path / "ds").write("a", _buffers(), {})
    store = TargetStore(tmp_path / "ds")
    values = np.random.default_rng(0).random((6, 6, 10)).astype(np.float32)
    store.write("a", "jnyang", values, (24, 40))
    store.write("a", "psnr", values, (24, 40))
    assert np.array_equal(store.load("a", "jnyang", 4 * 2**40), values.max(axis=(1, 2), keepdims=True))
    assert np.array_equal(store.load("a", "psnr", 4 * 2**40), store.load("a", "psnr", 40))
    for tile in (0, -4, 6, 4.0):
        with pytest.raises(TargetError, match="tile"):
            store.load("a", "jnyang", tile)  # type: ignore[arg-type]


def test_interrupted_write_leaves_nothing(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    w = DatasetWriter(tmp_path / "ds")

    def boom(*a: object, **k: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(KeyboardInterrupt):
        w.write("a", _buffers(), {})
    assert not w.has("a") and not list((tmp_path / "ds" / "samples").iterdir())


def test_reopening_requires_the_same_settings(tmp_path: Path) -> None:
    DatasetWriter(tmp_path / "ds", settings={"size": [40, 24]}).write("a", _buffers(), {})
    again = DatasetWriter(tmp_path / "ds", settings={"size": [40, 24]})
    assert again.has("a") and not again.has("b")
    # (the key that differs, with both values: it printed both whole dictionaries, to be compared by eye)
    with pytest.raises(DatasetError, match=r"other settings \(size: \[40, 24\] there, \[80, 48\] now\); use another"):
        DatasetWriter(tmp_path / "ds", settings={"size": [80, 48]})
    # a folder of another program's manifest is refused as it was: no samples/ made in it
    (tmp_path / "theirs").mkdir()
    (tmp_path / "theirs" / "manifest.json").write_text('{"format": "something-else"}')
    with pytest.raises(DatasetError, match="not an rtp dataset manifest"):
        DatasetWriter(tmp_path / "theirs")
    assert sorted(p.name for p in (tmp_path / "theirs").iterdir()) == ["manifest.json"]


def test_a_folder_that_holds_nothing_yet_takes_the_new_settings(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A job killed or refused before its first sample left its manifest: a rerun with a corrected option into the
    folder was refused as "captured with other settings" until the folder was deleted by hand, though nothing was
    made with them. Its settings are now replaced (a fresh manifest, as a new folder's), with a warning; a folder
    that holds a sample, a manifest listing one, or targets is refused as before."""
    import logging

    root = tmp_path / "ds"
    first = DatasetWriter(root, settings={"size": [40, 24], "depth_kind": "linear"})
    first.finalize({"failed": ["x/slow"]})
    (root / "samples" / ".a.npz.abc.tmp").write_bytes(b"cut short")  # (a killed write of the first sample)
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        w = DatasetWriter(root, settings={"size": [40, 24], "depth_kind": "reversed"})
    assert "holds no sample yet" in caplog.text and "depth_kind: 'linear' there, 'reversed' now" in caplog.text
    manifest = json.loads((root / "manifest.json").read_text())
    assert manifest == {"format": FORMAT, "format_version": FORMAT_VERSION,
                        "settings": {"size": [40, 24], "depth_kind": "reversed"}}
    w.write("a", _buffers(), {})
    with pytest.raises(DatasetError, match="other settings"):  # (one sample: refused, and left as it was)
        DatasetWriter(root, settings={"size": [40, 24]})
    assert json.loads((root / "manifest.json").read_text())["settings"]["depth_kind"] == "reversed"
    # the manifest lists samples (deleted since), or targets are there: refused too
    w.finalize()
    (root / "samples" / "a.npz").unlink()
    with pytest.raises(DatasetError, match="other settings"):
        DatasetWriter(root, settings={"size": [40, 24]})
    other = tmp_path / "targeted"
    DatasetWriter(other, settings={"size": [40, 24]})
    (other / "targets").mkdir()
    (other / "targets" / "manifest.json").write_text("{}")
    with pytest.raises(DatasetError, match="other settings"):
        DatasetWriter(other, settings={"size": [80, 48]})


def test_a_sample_of_another_size_than_the_manifests_is_refused_naming_the_file(tmp_path: Path) -> None:
    """A sample of another size than the manifest's settings say (one of another dataset copied in, or written by
    DatasetWriter with its settings' size not the frames') was written and read as it was: rtp train refused the mix
    much later, or trained a dataset of one size whose manifest says another. The writer refuses it, nothing written,
    and the reader names the file and both sizes."""
    import shutil

    w = DatasetWriter(tmp_path / "ds", settings={"size": [40, 24]})
    w.write("s0", _buffers(), {"scene": "a"})
    with pytest.raises(DatasetError, match=r"sample s1: its frames are 80x48, but .*ds's samples are 40x24 \(its "
                                           r"manifest's settings size\); nothing written"):
        w.write("s1", _buffers(48, 80), {"scene": "a"})
    assert not w.has("s1") and not list(w.samples_dir.glob(".*.tmp"))
    other = DatasetWriter(tmp_path / "other", settings={"size": [80, 48]})
    other.write("s1", _buffers(48, 80), {"scene": "a"})
    shutil.copy(other.samples_dir / "s1.npz", w.samples_dir / "s1.npz")
    reader = DatasetReader(tmp_path / "ds")
    assert reader.ids == ["s0", "s1"] and reader["s0"].size == (24, 40)
    with pytest.raises(DatasetError, match=re.escape(f"{w.samples_dir / 's1.npz'}: buffer 'seen' is 80x48, but the "
                                                     "dataset's manifest says its samples are 40x24 (settings size); "
                                                     "a damaged or foreign sample file: delete it")):
        reader["s1"].channel("seen")
    # a folder whose manifest gives no size (DatasetWriter without settings) takes any size, as before
    free = DatasetWriter(tmp_path / "free")
    free.write("a", _buffers(), {})
    free.write("b", _buffers(48, 80), {})
    assert DatasetReader(tmp_path / "free")["b"].size == (48, 80)


def test_the_formats_table_in_the_docs_is_what_the_writer_writes(tmp_path: Path) -> None:
    """docs/dataset.md "Format (version 1)": every buffer a sample file holds is in its table, with the dtype and
    the shape the writer stores it at, and nothing else is."""
    text = (Path(__file__).resolve().parents[1] / "docs" / "dataset.md").read_text(encoding="utf-8")
    section = text.split("## Format (version 1)", 1)[1].split("\n## ", 1)[0]
    documented: dict[str, tuple[str, str]] = {}
    for row in re.findall(r"^\| (`[^|]*) \| (\w+) (\([^)]*\)) \|", section, flags=re.M):
        names = re.findall(r"`([a-z_<>0-9]+)`", row[0])
        for name in names:
            for n in ([f"final_{r}" for r in sdk.ALL_RATES] if name == "final_<rate>" else [name]):
                documented[n] = (row[1], row[2].replace(" ", ""))
    w = DatasetWriter(tmp_path / "ds", settings={"size": [40, 24]})
    w.write("s0", _buffers(), {"scene": "a"})
    with np.load(w.samples_dir / "s0.npz") as npz:
        written = {k: (str(npz[k].dtype), "(" + ",".join(("H", "W", *map(str, npz[k].shape[2:]))) + ")")
                   for k in npz.files if k != "meta"}
    assert documented == written


def test_reader_errors(tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no dataset folder"):
        DatasetReader(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match="no manifest"):
        DatasetReader(tmp_path / "empty")
    w = DatasetWriter(tmp_path / "ds")
    (w.samples_dir / "bad.npz").write_bytes(b"junk")
    with pytest.raises(DatasetError, match="unreadable"):
        DatasetReader(tmp_path / "ds")["bad"]


def test_samples_the_manifest_lists_and_the_disk_lacks_are_said_once(tmp_path: Path,
                                                                      caplog: pytest.LogCaptureFixture) -> None:
    """A sample listed in the manifest and deleted from samples/ was skipped in silence (17 of 18 trained and
    evaluated, exit 0); `samples` as a file read as an empty dataset."""
    from rtp.capture import _dataset

    w = DatasetWriter(tmp_path / "ds")
    for i in range(4):
        w.write(f"s{i}", _buffers(seed=i), {"scene": "a"})
    w.finalize()
    (w.samples_dir / "s2.npz").unlink()
    (w.samples_dir / "folder.npz").mkdir()  # (no sample either)
    with caplog.at_level("WARNING", logger="rtp.capture"):
        assert DatasetReader(tmp_path / "ds").ids == ["s0", "s1", "s3"]
        DatasetReader(tmp_path / "ds")
    said = [r.getMessage() for r in caplog.records]
    assert said == [f"{tmp_path / 'ds'}: 1 of the 4 samples its manifest lists are not in samples/ (s2): deleted or "
                    "moved since the last capture? they are left out; the same rtp capture command captures them again"]
    _dataset._MISSING_SAID.clear()
    (tmp_path / "flat").mkdir()
    (tmp_path / "flat" / "manifest.json").write_text((tmp_path / "ds" / "manifest.json").read_text())
    (tmp_path / "flat" / "samples").write_text("")
    with pytest.raises(DatasetError, match="samples: expected the folder of the samples, found a file"):
        DatasetReader(tmp_path / "flat")


def test_the_manifest_lists_the_samples_a_reader_reads(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """finalize listed every ``*.npz`` in samples/: a file manager's copy ``s0 (1).npz`` or a folder ``x.npz``,
    which no reader reads, went into the manifest's ``samples``, and every reader then warned that the manifest's
    sample was missing and that a capture would capture it again (it would not)."""
    import shutil

    from rtp.capture import _dataset

    w = DatasetWriter(tmp_path / "ds")
    for i in range(2):
        w.write(f"s{i}", _buffers(seed=i), {"scene": "a"})
    shutil.copy(w.samples_dir / "s0.npz", w.samples_dir / "s0 (1).npz")
    (w.samples_dir / "x.npz").mkdir()
    w.finalize()
    manifest = json.loads((tmp_path / "ds" / "manifest.json").read_text())
    assert manifest["samples"] == ["s0", "s1"]
    assert manifest["bytes_per_sample"] == (sum((w.samples_dir / f"s{i}.npz").stat().st_size for i in range(2)) // 2)
    _dataset._MISSING_SAID.clear()
    with caplog.at_level("WARNING", logger="rtp.capture"):
        assert DatasetReader(tmp_path / "ds").ids == ["s0", "s1"]
    assert not caplog.records, [r.getMessage() for r in caplog.records]


def test_a_sample_file_with_an_id_too_long_is_left_out_with_a_warning(tmp_path: Path,
                                                                        caplog: pytest.LogCaptureFixture) -> None:
    """A sample file renamed (or an older rtp's) to an id longer than MAX_ID_LENGTH was listed, then refused by
    __getitem__: iterating the dataset (rtp targets, train, evaluate) failed on it."""
    from rtp.capture import _dataset

    w = DatasetWriter(tmp_path / "ds")
    for i in range(3):
        w.write(f"s{i}", _buffers(seed=i), {"scene": "a"})
    w.finalize()
    long = "level-" + "x" * (_dataset.MAX_ID_LENGTH - 5)
    (w.samples_dir / "s1.npz").rename(w.samples_dir / f"{long}.npz")
    w.finalize()  # (the manifest lists it: not said to be missing besides)
    with caplog.at_level("WARNING", logger="rtp.capture"):
        reader = DatasetReader(tmp_path / "ds")
        assert reader.ids == ["s0", "s2"] and [s.id for s in reader] == ["s0", "s2"]
        DatasetReader(tmp_path / "ds")  # (said once)
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and said[0].startswith(f"{tmp_path / 'ds'}: 1 sample file in samples/ has an id longer "
                                                 f"than 200 characters (level-xxx"), said
    assert f"{long[-20:]}.npz), which no sample has" in said[0] and "rename it to at most 200" in said[0], said


def test_a_manifest_that_is_a_folder_is_said_to_be_one(tmp_path: Path) -> None:
    """open_dataset and DatasetReader said "no manifest.json" of a folder that holds one (a folder)."""
    w = DatasetWriter(tmp_path / "ds")
    w.write("s0", _buffers(), {"scene": "a"})
    (tmp_path / "ds" / "manifest.json").unlink()
    (tmp_path / "ds" / "manifest.json").mkdir()
    for call in (open_dataset, DatasetReader, DatasetWriter):
        with pytest.raises(DatasetError, match=r"manifest.json is a folder, not the dataset's manifest file"):
            call(tmp_path / "ds")
    (tmp_path / "ds" / "manifest.json").rmdir()
    (tmp_path / "ds" / "manifest.json").symlink_to(tmp_path / "gone.json")
    with pytest.raises(DatasetError, match=r"manifest.json: a link to .*gone.json', which does not exist"):
        open_dataset(tmp_path / "ds")


def _rewrite(path: Path, **changes: np.ndarray | None) -> None:
    """Rewrite a sample archive with some members replaced (None: removed), as a corrupted file would be."""
    members = dict(np.load(path))
    members.update(changes)
    with open(path, "wb") as f:
        np.savez(f, **{k: v for k, v in members.items() if v is not None})  # type: ignore[arg-type]


def _npy_with_header(a: np.ndarray, old: str, new: str) -> bytes:
    import io

    buf = io.BytesIO()
    np.save(buf, a)
    raw = buf.getvalue()
    n = int.from_bytes(raw[8:10], "little")
    header = raw[10 : 10 + n].decode("latin1").replace(old, new)
    return raw[:8] + len(header).to_bytes(2, "little") + header.encode("latin1") + raw[10 + n :]


@pytest.mark.parametrize(
    ("corrupt", "words"),
    [
        (lambda p: np.save(p.open("wb"), np.zeros(3)), "not an .npz archive"),
        (lambda p: _rewrite(p, final_1x1=np.zeros(5, np.uint8)), "has shape (5,), expected (H, W, 3)"),
        (lambda p: _rewrite(p, normal=np.zeros((24, 40, 2), np.float16)), "expected (H, W, 3)"),
        (lambda p: _rewrite(p, albedo=np.zeros((10, 10, 3), np.uint8)), "the sample's other buffers are 40x24"),
        (lambda p: _rewrite(p, depth=np.full((24, 40), np.nan, np.float16)), "NaN or infinite"),
        (lambda p: _rewrite(p, depth=np.full((24, 40), 1j)), "stored as complex128, expected float16"),
        (lambda p: _rewrite(p, seen=np.zeros((24, 40), np.float64)), "stored as float64, expected uint8"),
        (lambda p: _rewrite(p, seen=None), "buffer 'seen' missing"),
        (lambda p: _rewrite(p, meta=np.zeros(3)), "unreadable sample"),
        (lambda p: _rewrite(p, meta=np.frombuffer(b"[1, 2]", np.uint8)), "meta is not a JSON object"),
    ],
    ids=["npy", "1-d", "channels", "size", "nan", "complex", "dtype", "missing", "meta-junk", "meta-list"],
)
def test_malformed_samples_are_dataset_errors(tmp_path: Path, corrupt: Any, words: str) -> None:
    w = DatasetWriter(tmp_path / "ds")
    w.write("s0", _buffers(), {"scene": "a"})
    corrupt(w.samples_dir / "s0.npz")
    with pytest.raises(DatasetError) as err:
        s = DatasetReader(tmp_path / "ds")["s0"]
        s.inputs(sdk.CHANNELS)
        for r in sdk.ALL_RATES:
            s.final(r)
    assert words in str(err.value)
    # the file is named (an id alone did not say which folder of several: rtp train --data a,b)
    assert str(w.samples_dir / "s0.npz") in str(err.value) or words in ("unreadable sample",), str(err.value)


def test_a_sample_file_damaged_inside_or_a_newer_format_says_what_to_do(tmp_path: Path) -> None:
    """A buffer damaged inside its file (the archive's index intact: a resumed capture keeps the file), missing or
    of another dtype, and a dataset of a newer format, were refused naming what was wrong and not what to do."""
    w = DatasetWriter(tmp_path / "ds")
    w.write("s0", _buffers(), {"scene": "a"})
    path = w.samples_dir / "s0.npz"
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF  # (inside a member's compressed bytes: its CRC fails when it is read)
    path.write_bytes(bytes(data))
    sample = DatasetReader(tmp_path / "ds")["s0"]
    with pytest.raises(DatasetError, match=r"is unreadable .*; a damaged or foreign sample file: delete it, and the "
                       r"command that wrote the dataset \(the same rtp capture or rtp import\) writes it again"):
        for name in BUFFERS:
            sample.buffer(name)
    for change, said in (({"seen": None}, "buffer 'seen' missing"),
                         ({"seen": np.zeros((24, 40), np.float64)}, "stored as float64, expected uint8")):
        w.write("s0", _buffers(), {"scene": "a"})
        _rewrite(path, **change)
        with pytest.raises(DatasetError, match=re.escape(said) + "; a damaged or foreign sample file: delete it"):
            DatasetReader(tmp_path / "ds")["s0"].channel("seen")
    manifest = json.loads((tmp_path / "ds" / "manifest.json").read_text())
    (tmp_path / "ds" / "manifest.json").write_text(json.dumps({**manifest, "format_version": 2}))
    with pytest.raises(DatasetError, match=r"dataset format 2 is newer than this rtp reads \(1\): upgrade rtp"):
        DatasetReader(tmp_path / "ds")


def test_a_mangled_npy_header_is_a_dataset_error(tmp_path: Path) -> None:
    """numpy parses .npy headers with the tokenizer: a mangled one raised tokenize.TokenError, a huge
    shape MemoryError; both come out as DatasetError naming the buffer."""
    import zipfile

    w = DatasetWriter(tmp_path / "ds")
    w.write("s0", _buffers(), {})
    path = w.samples_dir / "s0.npz"
    members = dict(np.load(path))
    for old, new in [("(24, 40)", "(24, 40"), ("(24, 40)", "(4000000000, 4000000000)")]:
        with zipfile.ZipFile(path, "w") as z:
            for k, v in members.items():
                z.writestr(f"{k}.npy", _npy_with_header(v, old, new) if k == "depth" else _npy_with_header(v, "", ""))
        with pytest.raises(DatasetError, match="buffer 'depth' is unreadable"):
            DatasetReader(tmp_path / "ds")["s0"].channel("depth")


def test_bad_roots_and_ids_are_dataset_errors(tmp_path: Path) -> None:
    for root in (5, None, "a" * 10000, "a\0b"):
        with pytest.raises(DatasetError):
            open_dataset(root)  # type: ignore[arg-type]
        with pytest.raises(DatasetError):
            DatasetReader(root)  # type: ignore[arg-type]
    w = DatasetWriter(tmp_path / "ds")
    w.write("s0", _buffers(), {})
    (tmp_path / "elsewhere.npz").write_bytes((w.samples_dir / "s0.npz").read_bytes())
    r = DatasetReader(tmp_path / "ds")
    for sid in ("../../elsewhere", 5, None, ""):
        with pytest.raises(DatasetError, match="no sample"):
            r[sid]  # type: ignore[index]
    with pytest.raises(DatasetError, match="channel names"):
        r["s0"].inputs("seen")
    paper = tmp_path / "paper" / "x"
    paper.mkdir(parents=True)
    (paper / "output_1x1.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(40))
    with pytest.raises(DatasetError, match="not a readable PNG"):
        open_dataset(tmp_path / "paper")["x"].final("1x1")


def _paper_sample(folder: Path, rng: np.random.Generator, size: tuple[int, int]) -> dict[str, np.ndarray]:
    """A sample folder of the paper's layout: every PNG it holds, random RGBA of ``size`` (H, W); returns them."""
    imgs = {}
    for stem in ["reproject_1x1", "diffuse_1x1", "specular_1x1", "emissive_1x1", "normals_1x1", "extra_1x1"] + [
        f"output_{r}" for r in sdk.ALL_RATES
    ]:
        imgs[stem] = rng.integers(0, 256, (*size, 4), dtype=np.uint8)
        write_png(folder / f"{stem}.png", imgs[stem])
    return imgs


def test_paper_layout(tmp_path: Path) -> None:
    folder = tmp_path / "Bistro" / "0000"
    imgs = _paper_sample(folder, np.random.default_rng(1), (16, 32))
    ds = open_dataset(tmp_path / "Bistro")
    assert isinstance(ds, PaperDatasetReader) and ds.ids == ["0000"]
    s = ds["0000"]
    np.testing.assert_array_equal(np.round(s.channel("seen") * 255), imgs["reproject_1x1"][..., 3])
    np.testing.assert_array_equal(np.round(s.channel("roughness") * 255), imgs["specular_1x1"][..., 3])
    np.testing.assert_array_equal(np.round(s.final("4x4") * 255), imgs["output_4x4"][..., :3])
    assert s.inputs(sdk.DEFAULT_INPUTS).shape == (4, 16, 32)
    with pytest.raises(DatasetError, match="no 'depth'"):
        s.channel("depth")
    with pytest.raises(DatasetError, match="the paper's layout has no 'depth' buffer"):
        s.buffer("depth")
    assert len(ds) == 1 and [x.id for x in ds] == ["0000"]
    for sid in ("0001", "..", "../Bistro/0000"):  # only the listed sample folders, never a path out of them
        with pytest.raises(DatasetError, match=f"no sample '{re.escape(sid)}'"):
            ds[sid]
    (folder / "specular_1x1.png").unlink()  # a sample folder missing one of its images
    with pytest.raises(DatasetError, match=r"missing file .*specular_1x1\.png"):
        ds["0000"].channel("roughness")  # (a fresh sample: s holds what it read)
    (tmp_path / "Empty" / "0000").mkdir(parents=True)  # folders, but none holds output_1x1.png
    with pytest.raises(DatasetError, match="no sample folders with output_1x1.png"):
        open_dataset(tmp_path / "Empty")
    (tmp_path / "Lost" / "samples").mkdir(parents=True)  # an rtp dataset whose manifest went: said as such
    with pytest.raises(DatasetError, match=r"Lost: no manifest\.json \(an rtp dataset's; its samples/ folder is here\)"):
        open_dataset(tmp_path / "Lost")


def test_paper_layout_refuses_a_mask_png_without_its_alpha(tmp_path: Path) -> None:
    """The paper's layout keeps the seen mask in ``reproject_1x1``'s alpha and roughness in ``specular_1x1``'s: an
    image re-saved without its alpha (RGB) read as alpha 1, every pixel seen and fully rough, in silence. It is a
    DatasetError naming the file; the colour planes of the same files still read, and a palette image with a
    transparent colour (a PNG's tRNS, read as alpha) is kept."""
    from PIL import Image

    folder = tmp_path / "Bistro" / "0000"
    imgs = _paper_sample(folder, np.random.default_rng(3), (8, 12))
    for stem in ("reproject_1x1", "specular_1x1"):
        Image.fromarray(imgs[stem][..., :3]).save(folder / f"{stem}.png")  # (RGB: its alpha dropped)
    s = open_dataset(tmp_path / "Bistro")["0000"]
    with pytest.raises(DatasetError, match=r"reproject_1x1\.png: no alpha channel, which holds the paper layout's seen"):
        s.channel("seen")
    with pytest.raises(DatasetError, match=r"specular_1x1\.png: no alpha channel, which holds the paper layout's "
                                           "roughness"):
        s.channel("roughness")
    np.testing.assert_array_equal(np.round(s.channel("reprojected.g") * 255), imgs["reproject_1x1"][..., 1])
    np.testing.assert_array_equal(np.round(s.channel("specular") * 255), imgs["specular_1x1"][..., 0])
    palette = Image.fromarray(np.where(imgs["reproject_1x1"][..., :1] > 127, 255, 0).astype(np.uint8)[..., 0], "L")
    palette.convert("P").save(folder / "reproject_1x1.png", transparency=0)  # (black transparent: unseen)
    seen = open_dataset(tmp_path / "Bistro")["0000"].channel("seen")
    np.testing.assert_array_equal(seen, (imgs["reproject_1x1"][..., 0] > 127).astype(np.float32))


def test_paper_layout_scene_is_the_folders_name_given_as_dot(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A sample of the paper's layout is of the scene its folder names: opened as ``.`` (``rtp preview .`` inside
    it) or ``..`` its scene was '' or '..' (the preview's title said "scene ,"); a link keeps the link's name."""
    folder = tmp_path / "Bistro" / "0000"
    for stem in ["reproject_1x1", "diffuse_1x1", "specular_1x1", "emissive_1x1", "normals_1x1", "extra_1x1"] + [
        f"output_{r}" for r in sdk.ALL_RATES
    ]:
        write_png(folder / f"{stem}.png", np.zeros((4, 4, 4), np.uint8))
    (tmp_path / "Link").symlink_to(tmp_path / "Bistro")
    monkeypatch.chdir(tmp_path / "Bistro")
    assert open_dataset(".")["0000"].meta["scene"] == "Bistro"
    assert open_dataset("./")["0000"].meta["scene"] == "Bistro"
    monkeypatch.chdir(folder)
    assert open_dataset("..")["0000"].meta["scene"] == "Bistro"
    assert open_dataset(tmp_path / "Link")["0000"].meta["scene"] == "Link"


def test_paper_layout_reads_16_bit_and_float_pngs_by_their_values(tmp_path: Path) -> None:
    """A sample of the paper's layout written with 16-bit greyscale or float images reads the values
    they hold (Pillow's convert('RGBA') clipped 16 bits to white); a float image past [0, 1] is a
    DatasetError naming the file, not a black buffer."""
    from PIL import Image

    folder = tmp_path / "Bistro" / "0000"
    rng = np.random.default_rng(2)
    grey = rng.integers(0, 256, (16, 32), dtype=np.uint8)
    for stem in ["reproject_1x1", "diffuse_1x1", "specular_1x1", "emissive_1x1", "normals_1x1", "extra_1x1"] + [
        f"output_{r}" for r in sdk.ALL_RATES
    ]:
        write_png(folder / f"{stem}.png", np.repeat(grey[..., None], 4, -1))
    Image.fromarray(grey.astype(np.uint16) * 257).save(folder / "diffuse_1x1.png")
    ds = open_dataset(tmp_path / "Bistro")
    np.testing.assert_allclose(ds["0000"].buffer("albedo"), np.repeat(grey[..., None] / 255, 3, -1), atol=1e-6)
    np.testing.assert_allclose(ds["0000"].channel("seen"), grey / 255, atol=1e-6)
    Image.fromarray(grey.astype(np.float32) / 255, "F").save(folder / "normals_1x1.png", format="TIFF")
    np.testing.assert_allclose(ds["0000"].buffer("normal")[..., 2], grey / 255, atol=1e-6)
    Image.fromarray(grey.astype(np.float32) / 100, "F").save(folder / "output_1x1.png", format="TIFF")
    with pytest.raises(DatasetError, match=r"output_1x1\.png: a float image with values in \[0\.01, 2\.55\]"):
        ds["0000"].final("1x1")


@pytest.mark.parametrize(("planes", "options"), [
    (3, {}), (4, {"alpha": True}), (2, {"greyscale": True, "alpha": True}), (3, {"interlace": True}),
    (3, {"transparent": (1, 2, 3)}),
])
def test_16_bit_pngs_are_read_with_all_16_bits(tmp_path: Path, planes: int, options: dict) -> None:
    """16-bit RGB, RGBA and greyscale-with-alpha PNGs (interlaced or with a transparent colour too), which Pillow
    reads with the top 8 bits a channel, give every value over 65535 (``read_image_values``), as the paper's layout
    reads them."""
    import png
    from PIL import Image

    from rtp.capture import image_values, read_image_values

    rng = np.random.default_rng(planes)
    a = rng.integers(0, 65536, (6, 10, planes), dtype=np.uint16)
    a[0, 0, : min(planes, 3)] = (1, 2, 3)[: min(planes, 3)]
    path = tmp_path / "a.png"
    with open(path, "wb") as f:
        png.Writer(10, 6, bitdepth=16, **{"greyscale": False, **options}).write(f, a.reshape(6, -1))
    colour = a[..., :3] if planes >= 3 else np.repeat(a[..., :1], 3, -1)
    has_alpha = planes in (2, 4) or "transparent" in options
    alpha = a[..., -1] if planes in (2, 4) else np.full(a.shape[:2], 65535)
    if "transparent" in options:
        alpha[0, 0] = 0
    np.testing.assert_allclose(read_image_values(path), colour / 65535, rtol=1e-6, atol=0)
    got = read_image_values(path, alpha=True)
    np.testing.assert_allclose(got, np.dstack([colour, alpha]) / 65535, rtol=1e-6, atol=0)
    assert got.dtype == np.float32 and has_alpha == (got[..., 3] < 1).any()
    with Image.open(path) as im:  # (what Pillow alone gives: the top 8 bits)
        assert np.abs(image_values(im) - colour / 65535).max() > 1 / 512
    folder = tmp_path / "Bistro" / "0000"
    for stem in ["reproject_1x1", "diffuse_1x1", "specular_1x1", "emissive_1x1", "normals_1x1", "extra_1x1"] + [
        f"output_{r}" for r in sdk.ALL_RATES
    ]:
        write_png(folder / f"{stem}.png", np.zeros((6, 10, 4), np.uint8))
    (folder / "diffuse_1x1.png").write_bytes(path.read_bytes())
    np.testing.assert_allclose(open_dataset(tmp_path / "Bistro")["0000"].buffer("albedo"), colour / 65535, rtol=1e-6, atol=0)


def test_a_damaged_16_bit_png_is_read_in_range_or_refused_as_os_or_value_error(tmp_path: Path) -> None:
    """A 16-bit PNG damaged under valid chunk checksums (its compressed or raw pixel data, its header, a stray
    chunk) is read to finite values in [0, 1] or refused with ``OSError`` or ``ValueError`` (Pillow's
    ``DecompressionBombError`` for a header claiming a huge image), which ``rtp metric`` and the dataset reader
    turn into their typed errors: pypng raised ``struct.error`` and ``IndexError`` (found by fuzzing it)."""
    import io
    import struct
    import zlib

    import png
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from PIL import Image

    from rtp.capture import read_image_values

    from .fuzzing import scaled

    def chunks(b: bytes) -> list[list[Any]]:
        out, i = [], 8
        while i < len(b):
            n = struct.unpack(">I", b[i:i + 4])[0]
            out.append([b[i + 4:i + 8], bytearray(b[i + 8:i + 8 + n])])
            i += 12 + n
        return out

    def build(cs: list[list[Any]]) -> bytes:  # (every chunk with its right CRC: the damage is inside them)
        return b"\x89PNG\r\n\x1a\n" + b"".join(struct.pack(">I", len(d)) + t + bytes(d)
                                              + struct.pack(">I", zlib.crc32(t + bytes(d)) & 0xFFFFFFFF) for t, d in cs)

    path = tmp_path / "damaged.png"

    @settings(max_examples=scaled(150), deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(st.data())
    def run(data: st.DataObject) -> None:
        planes = data.draw(st.sampled_from([2, 3, 4]))
        h, w = data.draw(st.integers(1, 8)), data.draw(st.integers(1, 8))
        a = np.random.default_rng(data.draw(st.integers(0, 99))).integers(0, 65536, (h, w, planes), dtype=np.uint16)
        buf = io.BytesIO()
        png.Writer(w, h, bitdepth=16, greyscale=planes == 2, alpha=planes in (2, 4),
                   interlace=data.draw(st.booleans())).write(buf, a.reshape(h, -1))
        cs = chunks(buf.getvalue())
        idat = next(c for c in cs if c[0] == b"IDAT")
        where = data.draw(st.sampled_from(["compressed", "raw", "header", "chunk"]))
        if where == "chunk":
            cs.insert(1, [data.draw(st.sampled_from([b"sBIT", b"tRNS", b"gAMA", b"PLTE"])),
                          bytearray(data.draw(st.binary(max_size=8)))])
        else:
            target = {"compressed": idat[1], "header": cs[0][1],
                      "raw": bytearray(zlib.decompress(bytes(idat[1])))}[where]
            for _ in range(data.draw(st.integers(1, 3))):
                target[data.draw(st.integers(0, len(target) - 1))] = data.draw(st.integers(0, 255))
            if where == "raw":
                cut = data.draw(st.integers(0, len(target)))
                idat[1] = bytearray(zlib.compress(bytes(target[:cut]) + data.draw(st.binary(max_size=40))))
        path.write_bytes(build(cs))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", Image.DecompressionBombWarning)
                v = read_image_values(path, alpha=data.draw(st.booleans()))
        except (OSError, ValueError, Image.DecompressionBombError):
            return
        assert v.dtype == np.float32 and v.ndim == 3 and v.shape[2] in (3, 4)
        assert np.isfinite(v).all() and v.min() >= 0 and v.max() <= 1

    run()


_PILLOW_MODES = ("1", "L", "LA", "La", "P", "PA", "RGB", "RGBA", "RGBa", "RGBX", "CMYK", "YCbCr", "LAB", "HSV", "I",
                 "I;16", "I;16L", "I;16B", "I;16N", "F")


def test_image_values_of_any_mode_and_bytes_are_colours_in_0_1_or_a_value_error() -> None:
    """Whatever Pillow mode and pixel bytes an image has, ``image_values`` gives finite float32 RGB(A)
    in [0, 1] of the image's size, or a ValueError saying what was expected (random float bytes:
    NaN, HDR)."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
    from PIL import Image

    from rtp.capture import image_values

    from .fuzzing import scaled

    seen: set[str] = set()

    @settings(max_examples=scaled(150), deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(st.sampled_from(_PILLOW_MODES), st.integers(1, 5), st.integers(1, 5), st.booleans(), st.data())
    def check(mode: str, w: int, h: int, alpha: bool, data: st.DataObject) -> None:
        size = len(Image.new(mode, (w, h)).tobytes())
        im = Image.frombytes(mode, (w, h), data.draw(st.binary(min_size=size, max_size=size)))
        try:
            a = image_values(im, alpha=alpha)
        except ValueError as err:
            assert mode in ("F", "I", "LAB") and "expected" in str(err) or "cannot convert" in str(err), (mode, err)
            seen.add(f"{mode} refused")
            return
        seen.add(mode)
        assert a.dtype == np.float32 and a.shape == (h, w, 4 if alpha else 3), (mode, a.shape)
        assert np.isfinite(a).all() and a.min() >= 0.0 and a.max() <= 1.0, mode

    check()
    assert len(seen) >= 5, seen  # (a random run: which modes it drew varies)
    # the kinds the draw must not miss, checked every run (a random run of 150 once drew no RGB image)
    for mode, raw, want in (("RGB", bytes(range(12)), 11 / 255), ("I;16", np.full(4, 65535, "<u2").tobytes(), 1.0),
                            ("F", np.full(4, 0.5, np.float32).tobytes(), 0.5)):
        a = image_values(Image.frombytes(mode, (2, 2), raw))
        assert a.dtype == np.float32 and a.shape == (2, 2, 3) and np.isclose(a.max(), want), (mode, a)
    with pytest.raises(ValueError, match="32-bit integer pixels: expected"):
        image_values(Image.frombytes("I", (2, 2), np.full(4, 7, np.int32).tobytes()))


def test_a_damaged_frame_file_is_a_parameter_error_naming_it(tmp_path: Path) -> None:
    """read_frame let zlib's raw error out of a deflate stream damaged past the arrays' headers (the CRC is only
    checked at the end of a member): `rtp predict damaged.npz` was a traceback; every damage is a ParameterError."""
    import zipfile

    from rtp.sdk.files import read_frame

    rng = np.random.default_rng(0)
    good = tmp_path / "good.npz"
    np.savez_compressed(good, depth=rng.random((96, 160), dtype=np.float32),
                        albedo=(rng.random((96, 160, 3)) > 0.5).astype(np.float32))
    with zipfile.ZipFile(good) as z:
        info = z.getinfo("albedo.npy")
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    kinds = set()
    for at in np.linspace(0.0, 1.0, 11):
        data = bytearray(good.read_bytes())
        off = start + 16 + int(at * (info.compress_size - 100))
        data[off:off + 64] = bytes(b ^ 0xFF for b in data[off:off + 64])
        bad = tmp_path / "damaged.npz"
        bad.write_bytes(bytes(data))
        with pytest.raises(sdk.ParameterError, match=r"damaged.npz': a damaged .npz, numpy cannot read its arrays \(") as e:
            read_frame(bad)
        kinds.add(str(e.value).split("(")[1].split(":")[0])
    assert "error" in kinds, kinds  # (zlib.error among them: the raw one before)


def test_atomic_files_get_ordinary_permissions(tmp_path: Path) -> None:
    import os

    from rtp.sdk.files import atomic_output

    with atomic_output(tmp_path / "f.bin") as tmp:
        tmp.write_bytes(b"x")
    mask = os.umask(0)
    os.umask(mask)
    assert (tmp_path / "f.bin").stat().st_mode & 0o777 == 0o666 & ~mask


def test_atomic_output_keeps_the_permissions_of_the_file_it_replaces(tmp_path: Path) -> None:
    """An ordinary open() and write keeps a file's permissions; atomic_output gave every rewrite 0o666 less the
    umask, so a model made private (chmod 600) came back readable by everyone, and a shared one (664) lost its
    group's write."""
    from rtp.sdk.files import atomic_output

    for mode in (0o600, 0o664, 0o640):
        target = tmp_path / f"m{mode:o}.onnx"
        target.write_bytes(b"old")
        os.chmod(target, mode)
        with atomic_output(target) as tmp:
            tmp.write_bytes(b"new")
        assert target.read_bytes() == b"new" and target.stat().st_mode & 0o777 == mode, oct(target.stat().st_mode)


def test_atomic_output_reads_the_umask_without_changing_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Reading the umask by setting it to 0 and back left a moment in which a file any other thread of the process
    created was writable by everyone; where the system shows the umask (Linux), it is read, not set."""
    from rtp.sdk.files import atomic_output

    try:
        shown = any(line.startswith("Umask:") for line in Path("/proc/self/status").read_text().splitlines())
    except OSError:
        shown = False
    if not shown:
        pytest.skip("the system does not show the umask in /proc/self/status")
    mask = os.umask(0o022)
    try:
        calls: list[int] = []
        real = os.umask
        monkeypatch.setattr(os, "umask", lambda m: calls.append(m) or real(m))
        with atomic_output(tmp_path / "f.bin") as tmp:
            tmp.write_bytes(b"x")
        monkeypatch.undo()
        assert calls == [] and (tmp_path / "f.bin").stat().st_mode & 0o777 == 0o644
    finally:
        os.umask(mask)


def test_a_writer_lock_refuses_a_second_holder_names_the_first_and_is_freed_with_it(tmp_path: Path) -> None:
    import subprocess
    import sys

    from rtp.sdk.files import LOCK_NAME, writer_lock

    class Busy(Exception):
        pass

    with writer_lock(tmp_path, "job one", Busy):
        assert (tmp_path / LOCK_NAME).read_text() == f"job one, pid {os.getpid()}"
        with pytest.raises(Busy, match=f"^job one, pid {os.getpid()}$"), writer_lock(tmp_path, "job two", Busy):
            pass  # (not reached)
    with writer_lock(tmp_path, "job two", Busy):  # freed at the end of the block, even though the file stays
        assert (tmp_path / LOCK_NAME).read_text() == f"job two, pid {os.getpid()}"
    holder = subprocess.Popen([sys.executable, "-c", "import sys, time; from rtp.sdk.files import writer_lock\n"
                               f"with writer_lock({str(tmp_path)!r}, 'sleeper', RuntimeError):\n"
                               "    print('held', flush=True); time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        with pytest.raises(Busy, match=f"^sleeper, pid {holder.pid}$"), writer_lock(tmp_path, "job three", Busy):
            pass
    finally:
        holder.kill()  # SIGKILL: no cleanup runs in the holder
        holder.wait()
    with writer_lock(tmp_path, "job three", Busy):  # the system freed it with the process
        pass


def test_a_removed_writer_lock_is_not_held_twice(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """remove=True deletes the lock file at the end; a process that opened the file just before that
    and locks it after would hold a lock nobody else sees: it finds the name gone and locks anew."""
    from rtp.sdk.files import writer_lock

    real_open, opened = os.open, []

    def racing_open(path: Any, flags: int, mode: int = 0o777) -> int:
        fd = real_open(path, flags, mode)
        opened.append(path)
        if len(opened) == 1:
            os.unlink(path)  # the holder ended and removed it between this open and the lock
        return fd

    monkeypatch.setattr(os, "open", racing_open)
    with writer_lock(tmp_path, "job", RuntimeError, name=".m.pt.lock", remove=True):
        assert (tmp_path / ".m.pt.lock").read_text() == f"job, pid {os.getpid()}"  # the file there now is held
    assert len(opened) == 2 and not (tmp_path / ".m.pt.lock").exists()


def test_a_file_system_without_locks_runs_the_job_with_a_warning(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    import errno
    import fcntl

    from rtp.sdk.files import writer_lock

    def no_locks(fd: int, op: int) -> None:
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "flock", no_locks)
    ran = []
    with caplog.at_level("WARNING", logger="rtp.sdk.files"), writer_lock(tmp_path, "rtp capture", RuntimeError):
        ran.append(1)
    assert ran and [r.getMessage().split(": ", 1)[1] for r in caplog.records] == [
        "this file system takes no locks (No locks available); rtp capture runs without its writer lock"]


def test_half_float_buffers_saturate_instead_of_overflowing(tmp_path: Path) -> None:
    w = DatasetWriter(tmp_path / "ds")
    bufs = _buffers()
    bufs["motion"][0, 0] = (1e6, -1e6)  # a point that was behind the previous camera
    w.write("s1", bufs, {})
    m = DatasetReader(tmp_path / "ds")["s1"].buffer("motion")
    assert np.isfinite(m).all() and m[0, 0, 0] == 65504.0 and m[0, 0, 1] == -65504.0


def test_a_uint8_seen_mask_of_0_and_1_is_refused_not_read_as_1_255(tmp_path: Path) -> None:
    """A uint8 buffer holds round(255 v), and the docs' table said seen is "uint8 (0 or 1)": a mask given as uint8
    0/1 (a bool mask's .astype(np.uint8)) was stored as it was and read back as 0 and 1/255, every pixel unseen."""
    w = DatasetWriter(tmp_path / "ds")
    bufs = _buffers()
    mask = bufs["seen"] > 0.5
    with pytest.raises(DatasetError, match=r"'seen': uint8 values 0 and 1, .*a seen pixel is 255"):
        w.write("a", {**bufs, "seen": mask.astype(np.uint8)}, {})
    assert not list((tmp_path / "ds" / "samples").iterdir())
    w.write("a", {**bufs, "seen": mask.astype(np.uint8) * 255}, {})  # (0/255 and float 0/1 are the mask)
    w.write("b", {**bufs, "seen": mask.astype(np.float32)}, {})
    w.write("c", {**bufs, "seen": np.zeros(mask.shape, np.uint8)}, {})  # (nothing seen: 0 either way)
    ds = DatasetReader(tmp_path / "ds")
    for sid in ("a", "b"):
        np.testing.assert_array_equal(ds[sid].channel("seen"), mask.astype(np.float32))
    assert not ds["c"].channel("seen").any()


def test_values_the_storage_would_misrepresent_are_refused_not_stored(tmp_path: Path) -> None:
    # uint8 normals were stored as float16 normals of 0-255; an albedo of 0-255 floats as all 1.0 (clipped)
    w = DatasetWriter(tmp_path / "ds")
    bufs = _buffers()
    with pytest.raises(sdk.InputDtypeError, match="'normal': uint8 values, but normal is stored as float16"):
        w.write("a", {**bufs, "normal": np.full((24, 40, 3), 128, np.uint8)}, {})
    with pytest.raises(DatasetError, match=r"'albedo': values in \[0, 255\], expected \[0, 1\].*divide them by 255"):
        w.write("a", {**bufs, "albedo": bufs["albedo"] * 0 + np.linspace(0, 255, 40, dtype=np.float32)[:, None]}, {})
    with pytest.raises(DatasetError, match="'seen': values in"):
        w.write("a", {**bufs, "seen": bufs["seen"] - 1.0}, {})
    assert not list((tmp_path / "ds" / "samples").iterdir())
    # an overshoot past [0, 1] (rounding, a sharpened final colour) is clipped as before; uint8 is taken for the
    # 8-bit buffers
    w.write("a", {**bufs, "albedo": bufs["albedo"] * 0 + 1.2, "final_1x1": (bufs["final_1x1"] * 255).astype(np.uint8)},
            {})
    assert DatasetReader(tmp_path / "ds")["a"].buffer("albedo").max() == 1.0


def test_meta_and_settings_json_cannot_hold_are_dataset_errors(tmp_path: Path) -> None:
    # (the json module's raw TypeError / ValueError before)
    w = DatasetWriter(tmp_path / "ds")
    bufs = _buffers()
    for meta, words in (({"unseen": np.float32(0.5)}, "float32"), ({"unseen": float("nan")}, "no NaN"),
                        ([("scene", "a")], "expected a mapping")):
        with pytest.raises(DatasetError, match=f"sample a: meta: .*{words}"):
            w.write("a", bufs, meta)  # type: ignore[arg-type]
    assert not list((tmp_path / "ds" / "samples").iterdir())
    with pytest.raises(DatasetError, match="settings: expected JSON values.*int64"):
        DatasetWriter(tmp_path / "other", {"seed": np.int64(3)})
    assert not (tmp_path / "other").exists()
    with pytest.raises(DatasetError, match="finalize: expected JSON values.*set"):
        w.finalize({"note": {1, 2}})
    # a file where the folder (or its samples/) is expected: the system's NotADirectoryError / FileExistsError before
    (tmp_path / "file").write_text("x")
    with pytest.raises(DatasetError, match="file: expected a folder, found a file"):
        DatasetWriter(tmp_path / "file")
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "samples").write_text("x")
    with pytest.raises(DatasetError, match="expected a folder of samples, found a file"):
        DatasetWriter(tmp_path / "s")


def test_images_of_other_integer_pixels_are_refused_not_saved_white(tmp_path: Path) -> None:
    from rtp.capture import save_image

    grey = np.full((4, 6, 3), 100, np.int64)  # (0-255 in int64: saved as white before)
    for write in (save_image, write_png):
        with pytest.raises(sdk.ParameterError, match="int64 pixels; expected uint8"):
            write(tmp_path / "a.png", grey)
        with pytest.raises(sdk.ParameterError, match="uint16 pixels"):
            write(tmp_path / "a.png", grey.astype(np.uint16))
        with pytest.raises(sdk.ParameterError, match=r"non-empty .* got shape \(0, 6, 3\)"):
            write(tmp_path / "a.png", np.zeros((0, 6, 3), np.float32))
        assert not (tmp_path / "a.png").exists()
        write(tmp_path / "b.png", grey.astype(np.uint8))
        write(tmp_path / "c.png", np.ones((4, 6), bool))
    from PIL import Image

    assert np.asarray(Image.open(tmp_path / "b.png"))[0, 0, 0] == 100
    assert np.asarray(Image.open(tmp_path / "c.png"))[0, 0] == 255
