"""Closed-loop VRS (``rtp play``): the renderer's rate-image shading and reprojection of any history,
the loop itself (each method's history is its own displayed frame), prediction reuse, the report."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.capture import load_scene
from rtp.capture.paths import DynamicResolution, PathFrame, PathPlayer, _source_across_sizes, camera_path, composite
from rtp.evaluate import PlayError, parse_methods, play, saved_at
from tests.conftest import make_current

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.gl
W, H, TILE = 160, 96, 16


@pytest.fixture(scope="module")
def scene() -> Any:
    return load_scene("procedural:0", None, None, None)


@pytest.fixture(scope="module")
def rendered(scene: Any, gl_context: Any) -> Any:
    """A renderer (FXAA off, so a composite is exact) left on the third frame of a fast path, and
    the two frames before it."""
    from rtp.plugins.moderngl import Renderer

    sc, blockers = scene
    path = camera_path(sc, 3, "fast", seed=2, blockers=blockers)
    r = Renderer(W, H, fxaa=False, ctx=make_current(gl_context))  # a module fixture runs before the autouse one
    r.load_scene(sc)
    frames, prev = [], None
    for cam in path.cameras:
        prev = r.render(cam, prev)
        frames.append(prev)
    yield r, frames
    r.release()


def test_rate_images_shade_each_tile_at_its_rate(rendered: Any) -> None:
    r, frames = rendered
    cur = frames[-1]
    th, tw = sdk.tile_grid(H, W, TILE)
    for rate, code in sdk.RATE_CODES.items():
        assert np.array_equal(r.shade_rates(np.full((th, tw), code, np.uint8), TILE), cur.colour[rate])
    codes = np.random.default_rng(0).choice(list(sdk.RATE_CODES.values()), (th, tw)).astype(np.uint8)
    assert np.array_equal(r.shade_rates(codes, TILE), composite(cur.colour, codes, TILE))  # no FXAA: exact


@pytest.mark.parametrize("hw", [(96, 160), (100, 170)])  # whole tiles, and ragged edge tiles
def test_composite_takes_each_tile_from_its_rate(hw: tuple[int, int]) -> None:
    """The block copy over whole tiles (and the per-pixel path for ragged edges) equals choosing each
    pixel from the image of its tile's rate."""
    rng = np.random.default_rng(1)
    h, w = hw
    colour = {rate: rng.random((h, w, 3), dtype=np.float32) for rate in sdk.RATE_CODES}
    codes = rng.choice(list(sdk.RATE_CODES.values()), sdk.tile_grid(h, w, TILE)).astype(np.uint8)
    want = np.empty((h, w, 3), np.float32)
    for y in range(h):
        for x in range(w):
            rate = next(k for k, v in sdk.RATE_CODES.items() if v == codes[y // TILE, x // TILE])
            want[y, x] = colour[rate][y, x]
    assert np.array_equal(composite(colour, codes, TILE), want)
    assert np.array_equal(composite(colour, codes.astype(np.int64), TILE), want)
    # 3: no rate's code; 10**12: past every code (it asked np.bincount for 7 TiB: a MemoryError)
    for bad in (np.full_like(codes, 3), np.full(codes.shape, -1), codes.astype(np.float32),
                np.where(codes == codes.flat[0], 10**12, codes.astype(np.int64))):
        with pytest.raises(sdk.ParameterError, match="rate codes"):
            composite(colour, bad, TILE)


@pytest.mark.parametrize("hw", [(96, 160), (100, 170)])
def test_composite_refuses_a_rate_image_of_another_tile_grid(hw: tuple[int, int]) -> None:
    """A rate image on other tiles (8-pixel ones given as 16-pixel ones) is refused, as Renderer.shade_rates refuses
    it: a larger grid was cropped to its top-left corner in silence, a smaller one an IndexError."""
    h, w = hw
    colour = {rate: np.full((h, w, 3), i, np.float32) for i, rate in enumerate(sdk.RATE_CODES)}
    th, tw = sdk.tile_grid(h, w, TILE)
    for shape in (sdk.tile_grid(h, w, TILE // 2), (th + 1, tw), (th, tw - 1), (th - 1, tw)):
        with pytest.raises(sdk.ParameterError, match=f"tile grid \\({th}, {tw}\\).*got shape"):
            composite(colour, np.full(shape, sdk.RATE_CODES["4x4"], np.uint8), TILE)
    for tile in (0, 16.0, True):
        with pytest.raises(sdk.ParameterError, match="tile_size: expected a positive integer"):
            composite(colour, np.zeros((th, tw), np.uint8), tile)  # type: ignore[arg-type]
    assert np.array_equal(composite(colour, np.full((th, tw), 10, np.uint8), TILE), colour["4x4"])


def test_composite_refuses_tiles_a_4x4_block_straddles_and_images_of_other_shapes() -> None:
    """A tile that is no multiple of 4 is refused as Renderer.shade_rates refuses it: the frame-aligned 4x4 blocks of the
    4x4 image straddled 6- (or 2-) pixel tiles, an image no per-tile VRS shades, returned in silence. A chosen rate's
    image of another shape than 1x1's with as many values ((W, H, C) for (H, W, C)) was reshaped into tiles in silence
    (other pixels), a missing one was a bare KeyError; both are a ParameterError naming the rate."""
    rng = np.random.default_rng(2)
    for tile in (2, 6, 12):
        h, w = 2 * tile, 3 * tile
        colour = {rate: rng.random((h, w, 3), dtype=np.float32) for rate in sdk.RATE_CODES}
        codes = np.full(sdk.tile_grid(h, w, tile), sdk.RATE_CODES["4x4"], np.uint8)
        codes[0, 0] = sdk.RATE_CODES["1x1"]
        if tile % 4 == 0:  # (12: whole 4x4 blocks in every tile)
            assert np.array_equal(composite(colour, codes, tile)[tile:, tile:], colour["4x4"][tile:, tile:])
            continue
        with pytest.raises(sdk.ParameterError, match=f"tile_size: expected a multiple of 4 pixels.*got {tile}"):
            composite(colour, codes, tile)
    h, w = 32, 48
    colour = {rate: rng.random((h, w, 3), dtype=np.float32) for rate in sdk.RATE_CODES}
    codes = np.full(sdk.tile_grid(h, w, TILE), sdk.RATE_CODES["1x1"], np.uint8)
    codes[1, 2] = sdk.RATE_CODES["2x2"]
    for image, got in ((rng.random((w, h, 3), dtype=np.float32), f"shape \\({w}, {h}, 3\\)"), (None, "none")):
        bad = dict(colour)
        if image is None:
            del bad["2x2"]
        else:
            bad["2x2"] = image
        with pytest.raises(sdk.ParameterError, match=f"colour\\['2x2'\\]: expected an image of the shape of "
                                                     f"colour\\['1x1'\\], \\({h}, {w}, 3\\).*got {got}"):
            composite(bad, codes, TILE)
        codes_1x1 = np.zeros_like(codes)  # (a rate no tile takes need not be there)
        assert np.array_equal(composite(bad, codes_1x1, TILE), colour["1x1"])
    with pytest.raises(sdk.ParameterError, match="colour: expected a frame's uniform-rate images.*'1x1'"):
        composite({"2x2": colour["2x2"]}, codes, TILE)


def test_any_history_reprojects_like_the_renderer(rendered: Any) -> None:
    r, frames = rendered
    prev, cur = frames[-2], frames[-1]
    rp, seen = r.reproject(prev.colour["1x1"], prev.depth, prev.camera)
    assert np.array_equal(rp, cur.reprojected) and np.array_equal(seen, cur.seen)
    rows, cols, seen2 = r.reprojection_source(prev.depth, prev.camera)
    other = prev.colour["4x4"]
    pf = PathFrame(2, cur, rows, cols, seen2)
    assert np.array_equal(pf.reproject(other), r.reproject(other, prev.depth, prev.camera)[0])
    # the gather is cached per frame: a second history reprojects through the same index
    again = prev.colour["1x2"]
    assert np.array_equal(pf.reproject(again), r.reproject(again, prev.depth, prev.camera)[0])
    assert np.array_equal(pf.plane("albedo.y"), sdk.luma(cur.albedo)) and pf.plane("albedo.y").dtype == np.float32
    assert pf.plane("normal.z") is pf.plane("normal.z")
    assert 0.3 < seen2.mean() < 1.0


def test_rate_images_and_histories_are_checked(rendered: Any) -> None:
    from rtp.plugins.moderngl import Renderer, RendererError

    r, frames = rendered
    th, tw = sdk.tile_grid(H, W, TILE)
    with pytest.raises(RendererError, match="tile grid"):
        r.shade_rates(np.zeros((th + 1, tw), np.uint8), TILE)
    with pytest.raises(RendererError, match="unknown rate codes"):
        r.shade_rates(np.full((th, tw), 3, np.uint8), TILE)
    with pytest.raises(RendererError, match="reproject: colour: expected a real array of shape"):
        r.reproject(np.zeros((H, W)), frames[0].depth, frames[0].camera)
    with Renderer(W, H, ctx=r.ctx) as fresh, pytest.raises(RendererError, match="render\\(\\) first"):
        fresh.shade_rates(np.zeros((th, tw), np.uint8), TILE)


def test_the_loop_is_closed(scene: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every history a method reprojects is an image it displayed on the frame before, never the
    full-rate frame; the report holds every method, and its pictures are written."""
    shaded: dict[int, int] = {}  # id of each displayed image -> the frame it was shown on
    full: set[int] = set()
    used: list[tuple[int, int]] = []  # (frame, id of the history reprojected into it)
    alive: list[Any] = []  # every image seen, kept so that no id is reused
    shade, frames_of, reproject = PathPlayer.shade, PathPlayer.frames, PathFrame.reproject
    current = [0]

    def spy_frames(self: PathPlayer, path: Any) -> Any:
        for pf in frames_of(self, path):
            current[0] = pf.index
            full.add(id(pf.frame.colour["1x1"]))
            alive.append(pf.frame)
            yield pf

    def spy_shade(self: PathPlayer, rates: np.ndarray, tile: int) -> np.ndarray:
        img = shade(self, rates, tile)
        shaded[id(img)] = current[0]
        alive.append(img)
        return img

    def spy_reproject(self: PathFrame, image: np.ndarray) -> np.ndarray:
        used.append((self.index, id(image)))
        return reproject(self, image)

    monkeypatch.setattr(PathPlayer, "frames", spy_frames)
    monkeypatch.setattr(PathPlayer, "shade", spy_shade)
    monkeypatch.setattr(PathFrame, "reproject", spy_reproject)
    rep = play("procedural:0", "jnyang,jnyang@2,jnyang@2:fresh,yang2019,fidelityfx,oracle,oracle-monotone,full",
               paths=("fast",),
               frames=5, size=(W, H), sweep=False, flip_every=2, out=tmp_path)
    assert len(used) == 5 * 4  # five methods with history, frames 1..4
    for frame, image in used:
        assert image not in full and shaded[image] == frame - 1
    rows = {r["method"]: r for r in rep.rows}
    assert set(rows) == {"jnyang", "jnyang@2", "jnyang@2:fresh", "yang2019", "fidelityfx", "oracle", "oracle-monotone",
                         "full"}
    assert rows["oracle"]["fail_share"] == 0 and rows["full"]["work_saved"] == 0 == rows["full"]["fail_share"]
    # the oracle on the monotone truth never fails either, and never saves more than the oracle on any frame
    assert rows["oracle-monotone"]["fail_share"] == 0
    assert all(m <= o for m, o in zip(rep.frames["fast"]["oracle-monotone"]["saved"], rep.frames["fast"]["oracle"]["saved"]))
    assert rows["jnyang@2"]["network_frames"] == 0.5 and rows["jnyang"]["network_frames"] == 1.0
    assert 0.5 <= rows["jnyang@2:fresh"]["network_frames"] <= 1.0  # plus crops around what it did not see
    assert 0 < rows["jnyang"]["work_saved"] < 1 and np.isfinite(rows["jnyang"]["flip_mean"])
    assert len(rep.unseen["fast"]) == 5 and rep.unseen["fast"][0] == 1.0
    for name in ("play.md", "play.json", "play_curves.png", "play_frames.png", "play_fast.gif"):
        assert (tmp_path / name).stat().st_size > 0
    settings = json.loads((tmp_path / "play.json").read_text())["settings"]
    assert settings["frames"] == 5 and settings["cameras"]["fast"]["length_m"] > 0
    assert settings["reuse"] == {"jnyang@2": {"k": 2, "reduce": "mean", "unseen": "full", "history": 0.0,
                                              "refresh": None, "step": 4, "rescale": 0.0, "carry_scale": 1.0,
                                              "carry": "estimates"},
                                 "jnyang@2:fresh": {"k": 2, "reduce": "mean", "unseen": "fresh",
                                                    "history": 0.0, "refresh": None, "step": 4,
                                                    "rescale": 0.0, "carry_scale": 1.0,
                                                    "carry": "estimates"}}  # what NAME@k meant
    assert abs(settings["cameras"]["fast"]["eye_height_m"] - 1.6) <= 0.125  # the procedural spawns' eye
    assert f"its eye {settings['cameras']['fast']['eye_height_m']:.2f} m over the floor" in (tmp_path / "play.md").read_text()
    assert "once every 2 frames." in (tmp_path / "play.md").read_text()
    # a path no longer than the FLIP interval has no FLIP'd frame: its "mean FLIP" column of dashes says why
    rep.settings["flip_every"] = 5
    assert "once every 5 frames (none of these 5: the first is frame 5)." in rep.to_markdown()
    # the several-map table reads the same file (bench/play_report.py, docs/results.md "Moving cameras")
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), str(tmp_path / "play.json"),
                          str(tmp_path / "play.json"), "--reuse", "jnyang@2,jnyang@2:fresh"],
                         capture_output=True, text=True, check=True).stdout
    # a savings row and a targets row: runs of one map and seed merge into one row per path
    assert out.count("| procedural:0 | 0 | fast |") == 2
    assert ("| jnyang / Yang | jnyang / oracle | jnyang / oracle-monotone | jnyang@2 / jnyang | jnyang@2:fresh / jnyang |"
            in out)
    assert "(network 50%)" in out  # the reuse columns give the network's work per frame
    assert "16-pixel tiles" in out
    # a run on other hardware tiles is another run, not merged (its rows were dropped, or its new methods put
    # in the other run's rows): each map row says its tiles
    eight = json.loads((tmp_path / "play.json").read_text())
    eight["settings"]["tile_size"] = 8
    (tmp_path / "play8.json").write_text(json.dumps(eight))
    both = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), str(tmp_path / "play.json"),
                           str(tmp_path / "play8.json")], capture_output=True, text=True, check=True).stdout
    assert both.count("| procedural:0 (16px) | 0 | fast |") == 2 and both.count("| procedural:0 (8px) | 0 | fast |") == 2
    assert "tiles as each map says" in both
    other = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), str(tmp_path / "play.json"),
                            "--model", "psnr"], capture_output=True, text=True, check=True).stdout
    assert "(No targets: the runs did not play psnr;" in other and "Targets" not in other
    # --window: each method's default, frame by frame, averaged over windows (frame 0 has no history)
    win = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), str(tmp_path / "play.json"),
                          "--window", "3"], capture_output=True, text=True, check=True).stdout
    assert "| frames 1-3 | frames 4-4 |" in win
    assert "jnyang@4 / jnyang" not in win  # no column for the default reuse method the run did not play
    series = json.loads((tmp_path / "play.json").read_text())["frames"]["fast"]["jnyang"]
    saved, fail = series["saved"][1:], series["fail"][1:]
    first = f"{100 * sum(saved[:3]) / 3:.1f} / {100 * sum(fail[:3]) / 3:.1f}"
    assert f"| procedural:0 | 0 | fast | jnyang | {first} | {100 * saved[3]:.1f} / {100 * fail[3]:.1f} |" in win
    # --by-age: jnyang@2's network runs on frames 0, 2, 4: frames 2 and 4 are age 0, frames 1 and 3 age 1;
    # beside it jnyang on the same frames (jnyang@2:fresh, which may restart its interval, is left out)
    age = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), str(tmp_path / "play.json"),
                          "--by-age"], capture_output=True, text=True, check=True).stdout
    age = age[age.index("by frames since"):]
    assert "| age 0 | age 1 |" in age and "jnyang@2:fresh" not in age
    for name, label in (("jnyang@2", "jnyang@2"), ("jnyang", "jnyang (same frames)")):
        sv, fl = (json.loads((tmp_path / "play.json").read_text())["frames"]["fast"][name][k] for k in ("saved", "fail"))
        cells = [f"{100 * (sv[a] + sv[b]) / 2:.1f} / {100 * (fl[a] + fl[b]) / 2:.1f}" for a, b in ((2, 4), (1, 3))]
        assert f"| procedural:0 | 0 | fast | {label} | {cells[0]} | {cells[1]} |" in age


def _spy_inputs(monkeypatch: pytest.MonkeyPatch) -> list[tuple[Any, np.ndarray | None]]:
    """Per network run of the loop: (the function building its inputs for a window, the history
    reprojected into that frame, None on the first)."""
    fed: list[tuple[Any, np.ndarray | None]] = []
    histories: list[np.ndarray] = []
    reproject, predict = PathFrame.reproject, sdk.PredictionReuse.predict

    def spy_reproject(self: PathFrame, image: np.ndarray) -> np.ndarray:
        histories.append(reproject(self, image))
        return histories[-1]

    def spy_predict(self: sdk.PredictionReuse, inputs: Any, *args: Any, **kwargs: Any) -> np.ndarray:
        fed.append((inputs, histories[-1] if histories else None))
        return predict(self, inputs, *args, **kwargs)

    monkeypatch.setattr(PathFrame, "reproject", spy_reproject)
    monkeypatch.setattr(sdk.PredictionReuse, "predict", spy_predict)
    return fed


def test_dynamic_resolution_is_a_schedule_of_sizes(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                   machine_memory: Callable[..., None]) -> None:
    dyn = DynamicResolution.parse("1,0.75@30")
    assert dyn == DynamicResolution((1.0, 0.75), 30)
    assert [dyn.size(i, (1280, 720)) for i in (0, 29, 30, 59, 60)] == [(1280, 720), (1280, 720), (960, 540), (960, 540),
                                                                      (1280, 720)]
    assert DynamicResolution((0.5, 1, 0.5), 1).sizes((100, 60)) == [(50, 30), (100, 60)]  # once each, in order
    assert DynamicResolution((0.01,), 1).size(0, (100, 60)) == (16, 16)  # at least 16 pixels a side
    # never past the full size: a side under 16 pixels is kept (a 12x8 path at scale 1 drew 16x16 frames)
    small = DynamicResolution((1.0, 0.5), 2)
    assert [small.size(i, (12, 8)) for i in (0, 2)] == [(12, 8), (12, 8)]
    assert small.sizes((40, 10)) == [(40, 10), (20, 10)] and small.size(2, (100, 20)) == (50, 16)
    for bad, match in (("0.75", "SCALES@FRAMES"), ("@3", "SCALES@FRAMES"), ("1,x@3", "SCALES@FRAMES"),
                       ("1@x", "SCALES@FRAMES"), ("1.5@3", r"in \(0, 1\]"), ("0@3", r"in \(0, 1\]"),
                       ("nan@3", r"in \(0, 1\]"), ("1@0", "integer >= 1")):
        with pytest.raises(sdk.ParameterError, match=match):
            DynamicResolution.parse(bad)
    for scales, every in (((), 3), ((True,), 3), (("1",), 3), ((10**400,), 3), ((1.0,), 2.5), ((1.0,), True)):
        with pytest.raises(sdk.ParameterError, match="dynamic resolution"):
            DynamicResolution(scales, every)  # type: ignore[arg-type]
    with pytest.raises(PlayError, match="dynamic_resolution: expected an rtp.capture.paths.DynamicResolution"):
        play("procedural:0", "full", frames=3, dynamic_resolution=((1.0, 0.5), 2))  # type: ignore[arg-type]
    # one renderer resized: the memory the run is refused by is the largest size's, before anything is written
    from rtp.capture import job_bytes

    need = job_bytes("play", (4096, 4096), metrics=("jnyang",), loops=1)
    machine_memory(MemTotal=need - 2**20, MemAvailable=need - 2**20)
    with pytest.raises(PlayError, match=rf"^size: the closed loop at 4096x4096 holds about {need / 2**30:.1f} GiB"):
        play("procedural:0", "oracle", frames=11, size=(4096, 4096), sweep=False, out=str(tmp_path / "out"),
             dynamic_resolution=DynamicResolution((1.0, 0.75, 0.5), 5))
    assert not (tmp_path / "out").exists()
    # rtp play --dynamic-resolution: a usage error (exit 2) in the same words
    from rtp.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["play", "procedural:0", "--dynamic-resolution", "1.5@3"])
    assert exc.value.code == 2 and "--dynamic-resolution: expected scales of the full size, numbers in (0, 1], got " \
        "1.5" in capsys.readouterr().err  # as given, not a tuple's repr


def test_a_schedule_the_path_ends_before_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A dynamic-resolution schedule whose later sizes a path of ``frames`` never reaches is refused before any work
    (``rtp play --frames 3 --dynamic-resolution 1,0.5@30`` played 3 frames at the full size, and play.md said they
    were drawn at 64x48 and 32x24 in turn); a schedule the path reaches is played."""
    from rtp.cli import main

    for frames, dyn, never, need in ((3, DynamicResolution((1.0, 0.5), 30), "32x24", 31),
                                     (10, DynamicResolution((1.0, 0.75, 0.5), 5), "32x24", 11)):
        with pytest.raises(PlayError, match=rf"^dynamic_resolution: each scale is held {dyn.every} frames, so a path "
                                            rf"of {frames} frames never draws {never}: give at least {need} frames"):
            play("procedural:0", "full", frames=frames, size=(64, 48), sweep=False, flip_every=0, plots=False,
                 out=tmp_path / "never", dynamic_resolution=dyn)
    assert main(["play", "procedural:0", "--frames", "3", "--size", "64x48", "--methods", "full", "--no-sweep",
                 "--dynamic-resolution", "1,0.5@30", "--out", str(tmp_path / "never")]) == 2
    err = capsys.readouterr().err
    assert "rtp play: error: --dynamic-resolution: each scale is held 30 frames, so a path of 3 frames never draws " \
           "32x24: give at least 31 frames" in err, err
    assert not (tmp_path / "never").exists()
    # a schedule the path reaches: frames 0-1 at 64x48, frame 2 at 32x24
    rep = play("procedural:0", "full", paths=("slow",), frames=3, size=(64, 48), sweep=False, flip_every=0,
               plots=False, dynamic_resolution=DynamicResolution((1.0, 0.5), 2))
    assert rep.settings["dynamic_resolution"]["sizes"] == [[64, 48], [32, 24]]


def test_a_one_size_schedule_says_every_frame_is_drawn_at_that_size() -> None:
    """`--dynamic-resolution 0.5@3` (one scale, or scales that round to one size) drew every frame at one size,
    and play.md said they were "drawn at 32x24 in turn, each size held 3 frames"; it says every frame is."""
    from rtp.evaluate._play import _dynamic_sentence

    kw: dict[str, Any] = {"paths": ("slow",), "frames": 3, "size": (64, 48), "sweep": False, "flip_every": 0,
                          "plots": False}
    text = play("procedural:0", "full", dynamic_resolution=DynamicResolution((0.5,), 3), **kw).to_markdown()
    assert " Dynamic resolution: every frame is drawn at 32x24 (scale 0.5 of the size); every method " in text, text
    assert "in turn" not in text and "each size held" not in text
    # scales that round to one size (at least 16 pixels a side) say so; two sizes are drawn in turn
    one = {"dynamic_resolution": {"scales": [0.1, 0.05], "every": 3, "sizes": [[16, 16]]}}
    assert _dynamic_sentence(one).startswith(
        " Dynamic resolution: every frame is drawn at 16x16 (scales 0.1, 0.05 of the size, all of them that size); ")
    assert _dynamic_sentence({"dynamic_resolution": {"scales": [1, 0.5], "every": 3, "sizes": [[64, 48], [32, 24]]}}
                             ).startswith(" Dynamic resolution: the frames are drawn at 64x48, 32x24 in turn, each size "
                                          "held 3 frames (scales 1, 0.5 of the size); ")


def test_a_frame_of_another_size_reprojects_as_the_renderer_does(scene: Any) -> None:
    """Dynamic resolution: each frame at its schedule's size; a frame after one of another size fetches from
    that frame's pixels (sdk.reproject of its pixel indices), which on frames of one size is the renderer's
    own GL reprojection to the pixel, seen and unseen alike; any history reprojects to this frame's size."""
    sc, blockers = scene
    path = camera_path(sc, 8, "fast", seed=1, blockers=blockers)
    sizes, prev, images = [], None, []
    with PathPlayer(sc, (W, H), dynamic=DynamicResolution((1.0, 0.5), 3)) as player:
        for pf in player.frames(path):
            h, w = pf.frame.depth.shape
            sizes.append((w, h))
            assert pf.rows.shape == pf.cols.shape == pf.seen.shape == (h, w)
            if prev is not None:
                ph, pw = prev.depth.shape
                assert 0 <= pf.rows.min() and pf.rows.max() < ph and 0 <= pf.cols.min() and pf.cols.max() < pw
                history = np.random.default_rng(pf.index).random((ph, pw, 3), dtype=np.float32)
                got = pf.reproject(history)
                assert got.shape == (h, w, 3)
                np.testing.assert_array_equal(got, np.where(pf.seen[..., None] > 0, history[pf.rows, pf.cols], 0))
                if (ph, pw) == (h, w):  # the SDK's reprojection against the renderer's, on frames of one size
                    rows, cols, seen = _source_across_sizes(pf.frame, prev)
                    assert np.array_equal(seen, pf.seen) and 0.2 < seen.mean()
                    assert np.mean((rows == pf.rows) & (cols == pf.cols)) > 0.999
                else:
                    assert 0.5 < pf.seen.mean() < 1.0  # (a camera that moves: most seen, not all)
            shaded = player.shade(np.zeros(sdk.tile_grid(h, w, TILE), np.uint8), TILE)
            np.testing.assert_array_equal(shaded, pf.frame.colour["1x1"])
            assert (player.renderer.width, player.renderer.height) == (w, h)  # (one renderer, resized)
            images.append(shaded)
            prev = pf.frame
    assert sizes == [(W, H)] * 3 + [(W // 2, H // 2)] * 3 + [(W, H)] * 2
    # a renderer of the caller's draws the same frames, and is given back at its own size
    from rtp.plugins.moderngl import Renderer

    with Renderer(W, H) as mine:
        mine.load_scene(sc)
        with PathPlayer(sc, renderer=mine, dynamic=DynamicResolution((1.0, 0.5), 3)) as player:
            for pf, image in zip(player.frames(path), images, strict=True):
                np.testing.assert_array_equal(pf.frame.colour["1x1"], image)
                if pf.index == 4:
                    break  # (closed at the smaller size)
        assert (mine.width, mine.height) == (W, H)
        mine.render(path.cameras[0])  # (and draws at it)


def test_a_history_reprojects_from_the_previous_frames_size_only(scene: Any) -> None:
    """PathFrame.reproject takes one plane (H, W) as it takes (H, W, C) (a plane was a ValueError of a reshape), and
    refuses an image of another size than the previous frame's: it fetched from one in silence, a larger one at the
    wrong pixels and a smaller one's indices clipped into it (under dynamic resolution, an image at the current
    frame's size given for the previous one's read other pixels without a word)."""
    rng = np.random.default_rng(0)
    h, w = 6, 10
    rows, cols = rng.integers(0, h, (h, w)), rng.integers(0, w, (h, w))
    rows[0, 0], cols[0, 0] = h - 1, w - 1
    seen = (rng.random((h, w)) > 0.3).astype(np.float32)
    image = rng.random((h, w, 3), dtype=np.float32)
    want = np.where(seen[..., None] > 0, image[rows, cols], 0)
    for known in ((h, w), None):
        pf = PathFrame(1, None, rows, cols, seen, source_size=known)
        assert np.array_equal(pf.reproject(image[..., 1]), want[..., 1])  # (a plane before the image: its own shape)
        assert np.array_equal(pf.reproject(image), want)
        for shape in ((h - 1, w, 3), (h, w - 1), (h, w + 2, 3), (h + 1, w)):
            if known is None and shape[0] >= h and shape[1] >= w:
                continue  # (the size not known: only an image too small for the fetch positions is told apart)
            with pytest.raises(sdk.ParameterError, match=f"previous frame's image, {w}x{h} pixels.*got "
                                                         f"{shape[1]}x{shape[0]}"):
                pf.reproject(np.zeros(shape, np.float32))
        with pytest.raises(sdk.ParameterError, match="\\(H, W, C\\) image or \\(H, W\\) plane"):
            pf.reproject(np.zeros((h, w, 3, 1), np.float32))
    # the player gives each frame its previous frame's size: dynamic resolution's current size is refused
    sc, blockers = scene
    path = camera_path(sc, 3, "fast", seed=1, blockers=blockers)
    sizes = []
    with PathPlayer(sc, (W, H), exact=False, dynamic=DynamicResolution((1.0, 0.5), 1)) as player:
        for pf in player.frames(path):
            sizes.append((pf.source_size, pf.frame.depth.shape))
            if pf.index > 0:  # (an image at this frame's size, not the previous one's)
                with pytest.raises(sdk.ParameterError, match="previous frame's image"):
                    pf.reproject(np.zeros((*pf.seen.shape, 3), np.float32))
    assert sizes == [(None, (H, W)), ((H, W), (H // 2, W // 2)), ((H // 2, W // 2), (H, W))]


def test_a_path_player_shades_no_frame_before_its_first(scene: Any) -> None:
    """Shading before frames() gave one was an AttributeError of None's colour with composite shading; it is the
    RendererError the renderer's own pass raises."""
    from rtp.plugins.moderngl import RendererError

    sc, _ = scene
    for exact in (False, True):
        with PathPlayer(sc, (W, H), exact=exact) as player, pytest.raises(RendererError, match="render\\(\\)|frames\\(\\)"):
            player.shade(np.zeros(sdk.tile_grid(H, W, TILE), np.uint8), TILE)


def test_dynamic_resolution_closes_the_loop_at_each_frames_size(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every history is the image the method displayed on the frame before, at that frame's size; prediction
    reuse carries across a change of size (the network still runs every k-th frame); the report says so."""
    shaded: dict[int, tuple[int, tuple[int, ...]]] = {}  # id of each displayed image -> (frame, its shape)
    used: list[tuple[int, int, tuple[int, ...]]] = []  # (frame, id of the history, this frame's shape)
    alive: list[Any] = []
    shade, frames_of, reproject = PathPlayer.shade, PathPlayer.frames, PathFrame.reproject
    current = [0]

    def spy_frames(self: PathPlayer, path: Any) -> Any:
        for pf in frames_of(self, path):
            current[0] = pf.index
            yield pf

    def spy_shade(self: PathPlayer, rates: np.ndarray, tile: int) -> np.ndarray:
        img = shade(self, rates, tile)
        shaded[id(img)] = (current[0], img.shape)
        alive.append(img)
        return img

    def spy_reproject(self: PathFrame, image: np.ndarray) -> np.ndarray:
        used.append((self.index, id(image), self.seen.shape))
        return reproject(self, image)

    monkeypatch.setattr(PathPlayer, "frames", spy_frames)
    monkeypatch.setattr(PathPlayer, "shade", spy_shade)
    monkeypatch.setattr(PathFrame, "reproject", spy_reproject)
    rep = play("procedural:0", "jnyang,jnyang@2,yang2019,fidelityfx,oracle", paths=("fast",), frames=7, size=(W, H),
               sweep=False, flip_every=2, out=tmp_path, dynamic_resolution=DynamicResolution((1.0, 0.5), 3))
    size_of = {i: (H, W) if i // 3 % 2 == 0 else (H // 2, W // 2) for i in range(7)}
    assert len(used) == 4 * 6  # four methods with history, frames 1..6
    for frame, image, shape in used:
        shown_on, shown_shape = shaded[image]
        assert shown_on == frame - 1 and shown_shape[:2] == size_of[frame - 1] and shape == size_of[frame]
    rows = {r["method"]: r for r in rep.rows}
    assert rows["jnyang@2"]["network_frames"] == 0.5  # frames 2, 4, 6 of 1..6: frame 3, a new size, carried
    assert rows["oracle"]["fail_share"] == 0 and 0 < rows["jnyang"]["work_saved"] < 1
    # no rate change is counted across a change of size (the tiles are others), every other frame's is
    change = rep.frames["fast"]["jnyang"]["change"]
    assert [np.isnan(c) for c in change] == [True, False, False, True, False, False, True]
    dyn = json.loads((tmp_path / "play.json").read_text())["settings"]["dynamic_resolution"]
    assert dyn == {"scales": [1.0, 0.5], "every": 3, "sizes": [[W, H], [W // 2, H // 2]]}
    from rtp.evaluate.plots import _smaller_frames  # (play_frames.png shades them)

    assert _smaller_frames(rep.settings, 7) == [(3, 6)] and (tmp_path / "play_frames.png").stat().st_size > 0
    assert _smaller_frames({**rep.settings, "dynamic_resolution": None}, 7) == []
    assert f"drawn at {W}x{H}, {W // 2}x{H // 2} in turn, each size held 3 frames" in (tmp_path / "play.md").read_text()
    import imageio.v3 as iio

    gif = iio.imread(tmp_path / "play_fast.gif", index=None)
    assert gif.ndim == 4 and len(gif) == 6  # (frame 0, without history, left out)
    # every GIF frame's panels the size of the full size's: a half-size frame's scaled up to them
    from rtp.evaluate._play import _ANIM_PANEL_WIDTH, _anim_frame

    for w, h in ((W, H), (1280, 720)):
        rng = np.random.default_rng(0)
        panels = [_anim_frame(img, {"m": (img, np.zeros(sdk.tile_grid(*img.shape[:2], TILE), np.uint8))}, TILE, "", (w, h))
                  for img in (rng.random((h, w, 3)), rng.random((h // 2, w // 2, 3)))]
        assert panels[0].shape == panels[1].shape == (round(h * min(w, _ANIM_PANEL_WIDTH) / w),
                                                      2 * min(w, _ANIM_PANEL_WIDTH), 3)  # (two panels in a row)


def test_no_rate_change_is_counted_across_sizes_of_one_tile_grid(tmp_path: Path) -> None:
    """Sizes whose tile grids are alike (160x96 and 158x95: 10x6 tiles of 16 pixels) are still other tiles: the rate
    change across them was counted, tile by tile, as if the frame had not changed size."""
    assert sdk.tile_grid(95, 158, TILE) == sdk.tile_grid(H, W, TILE)
    rep = play("procedural:0", "yang2019,oracle", paths=("slow",), frames=4, size=(W, H), sweep=False, flip_every=0,
               dynamic_resolution=DynamicResolution((1.0, 0.99), 2))
    assert rep.settings["dynamic_resolution"]["sizes"] == [[W, H], [158, 95]]
    for method in ("yang2019", "oracle"):
        change = rep.frames["slow"][method]["change"]
        assert [np.isnan(c) for c in change] == [True, False, True, False], (method, change)


def test_a_model_reading_luma_gets_the_luma_of_its_own_history(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A shipped model that reads reprojected.y (JNFLIP) is fed the luma of the method's own
    reprojected displayed frame, plane for plane what the dataset and the adapters give it."""
    meta = sdk.load("jnflip").metadata
    assert "reprojected.y" in meta.inputs and "albedo.y" in meta.inputs
    fed = _spy_inputs(monkeypatch)
    rep = play("procedural:0", "jnflip", paths=("fast",), frames=3, size=(W, H), sweep=False, flip_every=0, out=tmp_path)
    seen = [(inputs(slice(0, H), slice(0, W)), rp) for inputs, rp in fed]
    assert len(seen) == 3 and 0.0 <= {r["method"]: r for r in rep.rows}["jnflip"]["work_saved"] < 1.0
    assert seen[0][1] is None and all(rp is not None for _, rp in seen[1:])  # frame 0 has no history
    for x, rp in seen[1:]:
        assert rp is not None
        np.testing.assert_allclose(x[meta.inputs.index("reprojected.y")], sdk.luma(rp), atol=1e-6)
        assert x[meta.inputs.index("albedo.y")].max() > 0.0


@pytest.mark.parametrize("planes", ["blocks", "tiles"])
def test_a_splitting_model_carries_its_features_in_the_loop(tmp_path: Path, planes: str) -> None:
    """``NAME@k:features``: a splitting model's trunk runs every k-th frame, its tail on every frame; the
    loop records the network's share of frames and the carry it used."""
    from tests.conftest import split_model

    model = split_model(tmp_path, planes)
    name = f"{model}@2:features"
    rep = play("procedural:0", f"{model},{name}", paths=("fast",), frames=5, size=(W, H), sweep=False, flip_every=0)
    rows = {r["method"]: r for r in rep.rows}
    assert rows[name]["network_frames"] == 0.5 and rows[str(model)]["network_frames"] == 1.0
    assert 0.0 <= rows[name]["work_saved"] <= 1.0 and np.isfinite(rows[name]["fail_share"])
    assert rep.settings["reuse"][name]["carry"] == "features"


def test_the_default_methods_run_the_shipped_reuse_model_with_its_features() -> None:
    """``rtp play``'s defaults name only shipped models and include ``jnyang-reuse`` carrying its
    features; that model runs in the loop (its trunk every other frame here, its tail on each)."""
    from rtp.evaluate import DEFAULT_METHODS

    specs = parse_methods(DEFAULT_METHODS)
    shipped = {n.removesuffix(".onnx") for n in sdk.shipped_models()}
    assert {s.model for s in specs if s.kind == "model"} <= shipped
    assert any(s.model == "jnyang-reuse" and s.reuse == 4 and s.carry == "features" for s in specs)
    name = "jnyang-reuse@2:features"
    rep = play("procedural:0", f"jnyang-reuse,{name}", paths=("fast",), frames=5, size=(W, H), sweep=False,
               flip_every=0)
    rows = {r["method"]: r for r in rep.rows}
    assert rows[name]["network_frames"] == 0.5 and rows["jnyang-reuse"]["network_frames"] == 1.0
    assert rep.settings["reuse"][name]["carry"] == "features"


def test_a_model_reading_pixel_differences_gets_those_of_its_own_history(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, tiny_model: Any) -> None:
    """reprojected.y.dx / .dy and .blocks are sdk.pixel_differences and sdk.block_variances of the
    method's own reprojected history, albedo.y.blocks those of the frame's albedo, and
    a window of the frame (fresh crops) reads what the whole frame reads there, its last column and
    row included."""
    from tests.conftest import base_metadata

    model = tiny_model(base_metadata(inputs=["reprojected.y.dx", "seen", "reprojected.y", "reprojected.y.dy",
                                             "reprojected.y.blocks", "albedo.y.blocks", "albedo.y",
                                             "reprojected.y.tiles"]))
    fed = _spy_inputs(monkeypatch)
    play("procedural:0", str(model), paths=("fast",), frames=3, size=(W, H), sweep=False, flip_every=0, out=tmp_path)
    assert len(fed) == 3
    for inputs, rp in fed[1:]:
        assert rp is not None
        x = inputs(slice(0, H), slice(0, W))
        dx, dy = sdk.pixel_differences(sdk.luma(rp))
        np.testing.assert_allclose(x[0], dx, atol=1e-6)
        np.testing.assert_allclose(x[3], dy, atol=1e-6)
        assert dx.max() > 0.0 and dy.max() > 0.0
        np.testing.assert_allclose(x[4], sdk.block_variances(sdk.luma(rp)), atol=1e-6)
        np.testing.assert_allclose(x[7], sdk.tile_variances(sdk.luma(rp)), atol=1e-6)
        # albedo.y.blocks is the current G-buffer's, never the history's (the loop once gave a model
        # the reprojected frame's blocks under both names)
        np.testing.assert_allclose(x[5], sdk.block_variances(x[6]), atol=1e-6)
        assert x[5].max() > 0.0 and not np.allclose(x[5], x[4], atol=1e-3)
        np.testing.assert_allclose(inputs(slice(16, 48), slice(32, 96)), x[:, 16:48, 32:96], atol=1e-6)


@pytest.mark.parametrize("metric", ["lpips", "psnr"])
def test_tiles_fail_by_the_metric_the_run_names(metric: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """``fail_metric`` judges every method by that metric's true per-tile error of the frame (LPIPS,
    PSNR below its threshold, ...): each frame's failing share is the share of tiles whose chosen
    rate fails that metric's default threshold, and the oracle decides on the same values."""
    from rtp import metrics
    from rtp.evaluate import failing_tiles

    truths: list[np.ndarray] = []
    decided: list[np.ndarray] = []
    tile_targets, select_rates = metrics.tile_targets, sdk.select_rates

    def spy_targets(ref: np.ndarray, images: Any, names: Any, tile: int) -> dict[str, np.ndarray]:
        assert tuple(names) == (metric,)  # the loop computes the named metric and no other
        out = tile_targets(ref, images, names, tile)
        truths.append(out[metric])
        return out

    def spy_select(*args: Any, **kwargs: Any) -> np.ndarray:
        decided.append(select_rates(*args, **kwargs))
        return decided[-1]

    monkeypatch.setattr(metrics, "tile_targets", spy_targets)
    monkeypatch.setattr(sdk, "select_rates", spy_select)
    rep = play("procedural:0", f"{metric},oracle", paths=("fast",), frames=3, size=(W, H), sweep=False, flip_every=0,
               plots=False, fail_metric=metric)
    info = sdk.METRICS[metric]
    assert rep.settings["fail_threshold"] == info.default_threshold and len(truths) == 3 and len(decided) == 6
    series = rep.frames["fast"]
    for i, truth in enumerate(truths):  # per frame the model decides first, then the oracle
        model_rates, oracle_rates = decided[2 * i], decided[2 * i + 1]
        want = failing_tiles(model_rates, truth, info.default_threshold, info.higher_is_better).mean()
        assert series[metric]["fail"][i] == pytest.approx(want)
        assert series["oracle"]["fail"][i] == 0
        np.testing.assert_array_equal(oracle_rates, select_rates(truth, info.default_threshold,
                                                                  higher_is_better=info.higher_is_better))
    assert max(series[metric]["fail"]) > 0  # the test would see a wrong metric or direction
    rule = {"lpips": "its true lpips error is over 0.1", "psnr": "its true psnr is under 35"}[metric]
    assert f"A tile fails when {rule}; no FLIP of the displayed frames." in rep.to_markdown()
    with pytest.raises(PlayError, match="unknown metric 'no_such_metric'; metrics are flip, jnflip, psnr, lpips"):
        play("procedural:0", "oracle", frames=3, size=(W, H), fail_metric="no_such_metric")


def test_sweeps_reach_rare_failures(tmp_path: Path) -> None:
    rep = play("procedural:0", "jnyang,yang2019-unseen-1x1", paths=("slow",), frames=3, size=(W, H), flip_every=0,
               plots=False)
    from rtp.evaluate._play import BASELINE_SWEEP, MODEL_SWEEP, PSNR_SWEEP_DB, SAVING_SWEEP

    for method, grid in (("jnyang", MODEL_SWEEP), ("yang2019-unseen-1x1", BASELINE_SWEEP)):
        rows = [r for r in rep.rows if r["method"] == method]
        assert len(rows) == len(grid) and sum(r["default"] for r in rows) == 1
        assert min(r["fail_share"] for r in rows) <= 0.01
        # and one step past the default, for maps where the default fails rarely
        assert rows[-1]["fail_share"] >= next(r for r in rows if r["default"])["fail_share"]
    assert rep.settings["grids"] == {"model": list(MODEL_SWEEP), "psnr_db": list(PSNR_SWEEP_DB),
                                     "baseline": list(BASELINE_SWEEP), "saving": list(SAVING_SWEEP)}
    assert "| jnyang |" in rep.to_markdown()


def test_a_sweep_that_never_fails_as_often_is_a_lower_bound() -> None:
    """On an easy map a method can fail 0.8% of the tiles at its largest parameter: its saving at 5% is
    at least that run's, not a reading at 5%; the table says so and the ratios leave it out."""
    from rtp.evaluate import PlayReport

    rep = PlayReport(settings={"scene": "x", "frames": 3, "fps": 60, "seed": 0, "size": [64, 48], "tile_size": 16,
                               "fail_metric": "jnyang", "fail_threshold": 0.25, "flip_every": 0})
    rep.unseen["slow"] = [1.0, 0.0, 0.0]
    for method, saved, capped in (("jnyang", 0.826, True), ("yang2019", 0.865, False)):
        for level in (0.01, 0.02, 0.05):
            rep.matched.append({"path": "slow", "method": method, "fail_share": level, "work_saved": saved,
                                "capped": capped and level > 0.01})
    assert "| jnyang | 82.6% | >= 82.6% | >= 82.6% |" in rep.to_markdown()
    assert "| yang2019 | 86.5% | 86.5% | 86.5% |" in rep.to_markdown()
    assert np.isnan(rep.ratios("jnyang", "yang2019", 0.05)["slow"])
    assert rep.ratios("jnyang", "yang2019", 0.01)["slow"] == pytest.approx(0.826 / 0.865)
    rep.matched[2]["capped"] = False
    assert rep.ratios("jnyang", "yang2019", 0.05)["slow"] == pytest.approx(0.826 / 0.865)
    # a method the report does not hold (a typo) or a share it is not read at read NaN on every path, as if the
    # method could not reach it: both are refused, naming what there is
    with pytest.raises(PlayError, match=r"ratios: against: expected one of the report's methods \(jnyang, yang2019\), "
                                        r"got 'yang'"):
        rep.ratios("jnyang", "yang")
    with pytest.raises(PlayError, match="ratios: method: expected one of"):
        rep.ratios("JNYang", "yang2019")
    for level in (0.03, float("nan"), "0.05", None):
        with pytest.raises(PlayError, match=r"ratios: level: expected one of the matched table's failing shares "
                                            r"0.01, 0.02, 0.05, got"):
            rep.ratios("jnyang", "yang2019", level)  # type: ignore[arg-type]


def test_methods_are_parsed_and_checked(tmp_path: Path, machine_memory: Callable[..., None]) -> None:
    specs = parse_methods("jnyang, jnyang@4,models/psnr.onnx@2,yang2019,jnyang@4:worst,jnyang@4:mean,"
                          "jnyang@4:fresh,jnyang@2:fresh:upper,jnyang@1:h0.5,jnyang@4:h0.25:fresh,jnyang@8:r0.02,"
                          "jnyang@4:s4:r0.05,jnyang@4:v0.5:c1.08,split.onnx@4:features:fresh")
    assert [s.carry for s in specs] == ["estimates"] * 13 + ["features"]
    assert (specs[-1].model, specs[-1].reuse, specs[-1].unseen) == ("split.onnx", 4, "fresh")
    specs = specs[:-1]
    assert [s.step for s in specs] == [None] * 11 + [4, None]
    assert [s.rescale for s in specs] == [0.0] * 12 + [0.5]
    assert [s.carry_scale for s in specs] == [1.0] * 12 + [1.08]
    assert [(s.kind, s.model, s.reuse, s.reduce, s.unseen, s.history, s.refresh) for s in specs] == [
        ("model", "jnyang", 1, "mean", "full", 0, None), ("model", "jnyang", 4, "mean", "full", 0, None),
        ("model", "models/psnr.onnx", 2, "mean", "full", 0, None), ("yang2019", "", 1, "mean", "full", 0, None),
        ("model", "jnyang", 4, "worst", "full", 0, None), ("model", "jnyang", 4, "mean", "full", 0, None),
        ("model", "jnyang", 4, "mean", "fresh", 0, None), ("model", "jnyang", 2, "upper", "fresh", 0, None),
        ("model", "jnyang", 1, "mean", "full", 0.5, None), ("model", "jnyang", 4, "mean", "fresh", 0.25, None),
        ("model", "jnyang", 8, "mean", "full", 0, 0.02), ("model", "jnyang", 4, "mean", "full", 0, 0.05),
        ("model", "jnyang", 4, "mean", "full", 0, None)]
    for bad, match in (("jnyang@0", "reuse interval"), ("jnyang@x", "reuse interval"), ("", "at least one"),
                       ("oracle,oracle", "each method once"), ("jnyang@4:median", "worst, mean, upper"),
                       ("jnyang@4:", "worst, mean, upper"), ("jnyang@4:mean:worst", "at most one"),
                       ("jnyang@4:fresh:full", "full, fresh"), ("jnyang@1:h1.5", "history weight"),
                       ("jnyang@1:hx", "history weight"), ("jnyang@1:h0.5:h0.2", "at most one"), ("jnyang@8:r2", "refresh share"),
                       ("jnyang@8:r0.1:r0.2", "at most one"), ("jnyang@4:s0", "pixel step"), ("jnyang@4:sx", "pixel step"),
                       ("jnyang@4:s2:s4", "at most one"), ("jnyang@4:vx", "rescale exponent"),
                       ("jnyang@4:v3", "rescale exponent"), ("jnyang@4:v0.5:v1", "at most one"),
                       ("jnyang@4:c5", "carry scale"), ("jnyang@4:cx", "carry scale"), ("jnyang@²", "reuse interval"),
                       ("jnyang@4:s²", "pixel step"),
                       ("jnyang@4:c1.1:c1.2", "at most one"), ("jnyang@4:features:estimates", "at most one"),
                       ("jnyang@1:b0.95", r"not a budget: .* \[0, 0.9375\]"), ("jnyang@1:bx", "not a budget"),
                       ("jnyang@1:b0.5:b0.6", "at most one"), ("jnyang@1:f2", "not a floor"),
                       ("jnyang@1:f0.5:b0.5", "at most one"), ("jnyang@1:f0.5:f0.6", "at most one"),
                       ("jnyang@4:foo", "unknown option ':foo'; after '@k' expected at most one ':reduction'"),
                       ("jnyang@4:hist", "unknown option ':hist'")):
        with pytest.raises(PlayError, match=match):
            parse_methods(bad)
    # a model file whose name holds an '@' or a comma is taken whole, and '@k' after it still reuses
    for name in ("model@v2.onnx", "m,1.onnx"):
        (tmp_path / name).write_bytes(b"")
        path = str(tmp_path / name)
        assert [(s.kind, s.model, s.reuse) for s in parse_methods(path)] == [("model", path, 1)]
        assert [(s.kind, s.model, s.reuse) for s in parse_methods([path, "oracle"])] == [("model", path, 1),
                                                                                        ("oracle", "", 1)]
    assert parse_methods(str(tmp_path / "model@v2.onnx@4"))[0].model == str(tmp_path / "model@v2.onnx")
    with pytest.raises(PlayError, match="reuse interval"):  # (no such file: '@v2.onnx' is read as an interval)
        parse_methods(str(tmp_path / "other@v2.onnx"))
    with pytest.raises(sdk.ParameterError, match=r"divisor of the model's 16-pixel tile \(1, 2, 4, 8, 16\), got 3"):
        play("procedural:0", "jnyang@4:s3", frames=3, size=(64, 48), sweep=False)
    with pytest.raises(sdk.ParameterError, match="does not split"):
        play("procedural:0", "jnyang@4:features", frames=3, size=(64, 48), sweep=False)
    with pytest.raises(PlayError, match=r"method 'yang2109': not one of the methods \(full, oracle, .*\), so a model, "
                                        r"and no model file at 'yang2109'; shipped models: flip-8px.onnx, flip.onnx"):
        play("procedural:0", "jnyang,yang2109", frames=3, size=(64, 48), sweep=False)
    with pytest.raises(PlayError, match="unknown profile"):
        play("procedural:0", "oracle", paths=("sprint",), frames=3)
    with pytest.raises(PlayError, match="at least 3"):
        play("procedural:0", "oracle", frames=2)
    for tile in (3, 6, 0):  # (the VRS pass refused 3 and 6 only after the first frame, as a RendererError)
        with pytest.raises(PlayError, match="multiple of 4"):
            play("procedural:0", "full", frames=3, size=(64, 48), tile_size=tile, sweep=False)
    # strings for numbers were compared or passed on (a TypeError deep in the run, or "no" read as True), and
    # a string paths was split into its letters ("unknown profile 'f'")
    for kwargs, words in (({"frames": "5"}, "frames: expected an integer"), ({"fps": "60"}, "fps: expected a finite"),
                          # (a mistyped count planned its path for days without a word)
                          ({"frames": 36_001}, r"^frames: expected at most 36000 a path \(ten minutes at 60 frames"),
                          ({"fps": 0.001}, r"^fps: 3 frames at 0.001 frames a second last 2,000 s; expected a path of at "
                                           r"most 600 s \(ten minutes\): more frames a second, or fewer frames"),
                          ({"fps": float("nan")}, "fps"), ({"flip_every": 2.5}, "flip_every"),
                          ({"fps": 10**400}, "fps: expected a finite"),  # (an OverflowError, untyped)
                          ({"size": (64.0, 48)}, "size"), ({"size": "64x48"}, "size"), ({"seed": -1}, "seed"),
                          ({"workers": 0}, "workers"), ({"unseen_fraction": "0.5"}, "unseen_fraction"),
                          ({"sweep": "no"}, "sweep: expected True or False"), ({"open_loop": 1}, "open_loop"),
                          ({"fail_threshold": "0.3"}, "fail_threshold: expected a number"),
                          ({"fail_threshold": -1.0}, "fail_threshold"), ({"paths": []}, "paths"),
                          ({"paths": "sprint"}, "unknown profile 'sprint'")):
        with pytest.raises(PlayError, match=words):
            play("procedural:0", "full", **{"frames": 3, "size": (64, 48), **kwargs})  # type: ignore[arg-type]
    # a size this OpenGL cannot draw fails before the output folder is made (it was after the scene loaded)
    machine_memory(MemTotal=24 * 2**30, MemAvailable=20 * 2**30)  # a machine like this one
    with pytest.raises(PlayError, match=r"^size: the closed loop at 16384x16384 holds about 16\d\.\d GiB"):
        play("procedural:0", "full", frames=3, size=(16384, 16384), out=str(tmp_path / "out"))
    machine_memory(MemTotal=2**50, MemAvailable=2**50)  # on a machine with the memory: the renderer's refusal
    with pytest.raises(sdk.RtpError, match="frame size|render targets"):
        play("procedural:0", "full", frames=3, size=(16384, 16384), out=str(tmp_path / "out"))
    assert not (tmp_path / "out").exists()


def test_a_path_given_twice_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A profile given twice is refused before any work (``rtp play --path slow,slow`` played it once and reported
    it twice: each row of its table twice, its pictures listed twice, the progress bar left at half its count)."""
    from rtp.cli import main

    for paths in (("slow", "slow"), ["fast", "slow", "fast"]):
        with pytest.raises(PlayError, match=rf"^paths: each profile once, got {', '.join(paths)}$"):
            play("procedural:0", "full", paths=paths, frames=3, size=(64, 48), sweep=False, flip_every=0,
                 plots=False, out=tmp_path / "never")
    for argv in (["--path", "slow,slow"], ["--path", "slow", "--path", "fast,slow"]):
        assert main(["play", "procedural:0", "--frames", "3", "--size", "64x48", "--methods", "full", "--no-sweep",
                     "--out", str(tmp_path / "never"), *argv]) == 2
        err = capsys.readouterr().err
        assert "rtp play: error: --path: each profile once, got slow, " in err, err
    assert not (tmp_path / "never").exists()


def test_a_combiner_without_engine_rates_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--combiner meets --engine-rates' rates with each method's: given without them it is refused, not ignored
    (``rtp play --combiner sum`` ran and reported a run without engine rates, exit 0)."""
    from rtp.cli import main

    for combiner in ("min", "max", "sum"):
        assert main(["play", "procedural:0", "--frames", "3", "--size", "64x48", "--methods", "full", "--no-sweep",
                     "--out", str(tmp_path / "never"), "--combiner", combiner]) == 2
        err = capsys.readouterr().err
        assert f"rtp play: error: --combiner {combiner}: the hardware's combiner of --engine-rates' rates and each " \
               "method's; give --engine-rates" in err, err
    for combiner in ("min", "sum"):  # (the library's default, max, is what a call without engine_rates leaves)
        with pytest.raises(PlayError, match=rf"^combiner: .* without engine_rates \(--engine-rates\) there is nothing "
                                            rf"for '{combiner}' to combine"):
            play("procedural:0", "full", frames=3, size=(64, 48), sweep=False, flip_every=0, plots=False,
                 combiner=combiner, out=tmp_path / "never")
    assert not (tmp_path / "never").exists()


def test_a_budget_saves_its_share_on_every_frame(tmp_path: Path) -> None:
    """``NAME@k:bS``: every frame's rates save at least S of the work (the tiles weighed by their pixels: the
    96-pixel-tall frame's last row is whole, the 72-pixel one's half), a tile's step over it at most, while the
    threshold mode's saving follows the frames; swept, the budget's grid replaces the thresholds."""
    specs = parse_methods("jnyang@1:b0.6,jnyang@4:fresh:b0.3,jnyang@4:f0.5:full,jnyang-reuse@4:features:f0.4")
    assert [(s.budget, s.floor, s.reuse, s.unseen, s.carry) for s in specs] == [
        (0.6, None, 1, "full", "estimates"), (0.3, None, 4, "fresh", "estimates"), (None, 0.5, 4, "full", "estimates"),
        (None, 0.4, 4, "full", "features")]
    assert (parse_methods("jnyang")[0].budget, parse_methods("jnyang")[0].floor) == (None, None)
    # Yang 2019 takes a budget too (its estimates through the same selection); the other baselines no option
    yang = parse_methods("yang2019:b0.5,yang2019-unseen-1x1:b0.7")
    assert [(s.name, s.kind, s.budget) for s in yang] == [("yang2019:b0.5", "yang2019", 0.5),
                                                          ("yang2019-unseen-1x1:b0.7", "yang2019-unseen-1x1", 0.7)]
    for bad, words in (("fidelityfx:b0.5", "only Yang 2019 takes an option"), ("yang2019:x", "only Yang 2019"),
                       ("yang2019:b1.5", "the share of the shading work to save every frame"),
                       ("oracle:b0.5", "only Yang 2019 takes an option")):
        with pytest.raises(PlayError, match=words):
            parse_methods(bad)
    raised = 0
    for h, tile in ((H, 16), (72, 16), (72, 8)):
        rep = play("procedural:0", "jnyang,jnyang@1:b0.6,jnyang@2:b0.4,jnyang@1:f0.6,yang2019:b0.5", paths=("fast",),
                   frames=4, size=(W, h), sweep=False, flip_every=0, tile_size=tile, plots=False)
        # a floor: the threshold's saving where it is 0.6 or more, else the floor's, a tile's step over it at most
        # (compared up to the first frame the floor raised: from there each loop's history is its own)
        for own, floored in zip(rep.frames["fast"]["jnyang"]["saved"], rep.frames["fast"]["jnyang@1:f0.6"]["saved"]):
            if own >= 0.6:
                assert floored == own
                continue
            assert 0.6 - 1e-9 <= floored <= 0.6 + sdk.MAX_SAVING * 256 / (W * h)
            raised += 1
            break
        step = sdk.MAX_SAVING * 16 * 16 / (W * h)  # one 16-pixel model tile's whole saving
        for name, share in (("jnyang@1:b0.6", 0.6), ("jnyang@2:b0.4", 0.4), ("yang2019:b0.5", 0.5)):
            saved = rep.frames["fast"][name]["saved"][1:]  # (Yang's first frame has no history: all at 1x1 or not)
            assert all(share - 1e-9 <= v <= share + step for v in saved), (h, tile, name, saved)
        free = rep.frames["fast"]["jnyang"]["saved"]
        assert max(free) - min(free) > step  # (a threshold holds the quality: its saving moves)
    assert raised >= 2  # (the floor raised a frame in most runs)
    swept = play("procedural:0", "jnyang,jnyang@1:b0.55,yang2019:b0.55", paths=("slow",), frames=3, size=(W, H),
                 flip_every=0, plots=False)
    from rtp.evaluate._play import SAVING_SWEEP

    for name in ("jnyang@1:b0.55", "yang2019:b0.55"):
        assert [r["value"] for r in swept.rows if r["method"] == name] == sorted({*SAVING_SWEEP, 0.55})
        assert [r["parameter"] for r in swept.rows if r["method"] == name and r["default"]] == ["saving 0.55"]
    rows = [r for r in swept.rows if r["method"] in ("jnyang@1:b0.55", "yang2019:b0.55")]
    assert all(r["work_saved"] >= r["value"] - 1e-9 for r in rows)
    assert all(r["work_saved_p05"] >= r["value"] - 1e-9 for r in rows)
    for r in (r for r in swept.rows if r["default"]):  # the worst 5% of frames' saving (frame 0 has no history)
        series = swept.frames["slow"][r["method"]]["saved"][1:]
        assert r["work_saved_p05"] == pytest.approx(float(np.percentile(series, 5))) and len(series) == 2
    # the matched table reads the worst frames' saving off the same sweep, and play.md shows it
    for m in swept.matched:
        pts = [(r["fail_share"], r["work_saved_p05"]) for r in swept.rows if r["method"] == m["method"]]
        want = saved_at(pts, m["fail_share"])
        assert (m["work_saved_p05"] == pytest.approx(want)) if want is not None else np.isnan(m["work_saved_p05"])
    assert "The worst 5% of frames' saving where the method fails those shares of tiles" in swept.to_markdown()


def test_saved_at_reads_the_sweep() -> None:
    pts = [(0.0, 0.1), (0.02, 0.3), (0.10, 0.6)]
    assert saved_at(pts, 0.01) == pytest.approx(0.2)
    assert saved_at(pts, 0.02) == pytest.approx(0.3)
    assert saved_at(pts, 0.5) == pytest.approx(0.6)
    assert saved_at([(0.05, 0.5)], 0.01) is None
    # a point that fails more and saves less (a noisy closed-loop sweep) does not pull the reading below a point
    # that fails at most the share: at 1% the parameter failing 0% and saving 60% is there to run (it read 20%)
    assert saved_at([(0.0, 0.6), (0.005, 0.2)], 0.01) == pytest.approx(0.6)
    assert saved_at([(0.0, 0.6), (0.03, 0.2)], 0.01) == pytest.approx(0.6)  # (it read 46.7%)
    assert saved_at([(0.0, 0.5), (0.02, 0.4), (0.04, 0.9)], 0.01) == pytest.approx(0.5)
    assert saved_at([(0.0, 0.5), (0.02, 0.4), (0.04, 0.9)], 0.03) == pytest.approx(0.65)  # (upwards, as before)


def test_paths_in_worker_processes_give_the_same_report(caplog: pytest.LogCaptureFixture) -> None:
    import logging

    kw: dict[str, Any] = {"paths": ("slow", "fast"), "frames": 3, "size": (W, H), "sweep": False, "flip_every": 0,
                          "plots": False}
    ticks: list[int] = []
    stages: list[list[str]] = [[], []]
    one = play("procedural:0", "jnyang,yang2019", stage=stages[0].append, **kw)
    with caplog.at_level(logging.INFO):
        two = play("procedural:0", "jnyang,yang2019", workers=2, progress=ticks.append, stage=stages[1].append, **kw)
    assert sum(ticks) == 6
    # -v: each path's time, logged in its worker process and handled in this one
    timed = [r for r in caplog.records if "frames of 2 loops played in" in r.getMessage()]
    assert sorted(r.getMessage().partition(":")[0] for r in timed) == ["fast", "slow"]
    assert all(r.process != os.getpid() for r in timed)
    # what each path does between its frames is heard from the workers too (on the tick queue)
    assert sorted(stages[1]) == sorted(stages[0]) and len(stages[0]) == 12, stages
    for p in ("slow", "fast"):  # each path's steps in order: "playing" once its frames count, "done" at its end
        mine = [s.partition(": ")[2] for s in stages[1] if s.startswith(f"{p}: ")]
        assert mine[3:] == ["the first frame (rendered at every rate, then each method)", "playing", "done"], mine
    def timeless(rows: list[dict[str, Any]]) -> str:  # the choosing times differ from run to run
        return json.dumps([{k: v for k, v in r.items() if k != "predict_ms"} for r in rows])

    assert len(one.rows) == 4 and timeless(one.rows) == timeless(two.rows)


def test_more_workers_than_paths_say_how_many_processes_play(monkeypatch: pytest.MonkeyPatch,
                                                              caplog: pytest.LogCaptureFixture) -> None:
    """`rtp play --workers 4` with one path played it in this process without a word (as capture and targets,
    a process a path at most); it says so before the work, and how many processes play where there are more
    paths. As many workers as paths, or one, say nothing."""
    import logging

    from rtp.evaluate import _play

    class Started(Exception):
        pass

    def started(settings: Any) -> Any:  # (the work begins: nothing is played)
        raise Started

    monkeypatch.setattr(_play, "PlayReport", started)
    kw: dict[str, Any] = {"frames": 3, "size": (W, H), "sweep": False, "flip_every": 0, "plots": False}
    said: list[list[str]] = []
    for paths, workers in ((("fast",), 4), (("slow", "fast"), 3), (("slow", "fast"), 2), (("fast",), 1)):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="rtp.evaluate"), pytest.raises(Started):
            play("procedural:0", "jnyang", paths=paths, workers=workers, **kw)
        said.append([r.getMessage() for r in caplog.records if "workers" in r.getMessage()])
    assert said == [["workers 4 for 1 path (fast): a process a path at most, so it is played in this process"],
                    ["workers 3 for 2 paths (slow, fast): a process a path at most, so 2 processes play them"], [], []]


def test_a_play_into_another_runs_folder_says_it_replaces_that_report(tmp_path: Path,
                                                                       caplog: pytest.LogCaptureFixture) -> None:
    """A second `rtp play --out` into a folder holding another run's report (other methods, frames, map ...)
    replaced it at the end without a word (a ten-minute benchmark lost); it warns before the work, naming what
    differs. The same run again, or a first one, says nothing."""
    import logging

    kw: dict[str, Any] = {"paths": ("fast",), "frames": 3, "size": (W, H), "sweep": False, "flip_every": 0,
                          "plots": False, "out": tmp_path}
    with caplog.at_level(logging.WARNING, logger="rtp.evaluate"):
        play("procedural:0", "jnyang", **kw)
        play("procedural:0", "jnyang", **kw)
        assert "another run" not in caplog.text
        play("procedural:0", "jnyang,oracle", **{**kw, "frames": 4})
    (warning,) = [r.getMessage() for r in caplog.records if "another run" in r.getMessage()]
    assert warning.startswith(f"{tmp_path} holds the report of another run (methods, frames differ)")
    assert json.loads((tmp_path / "play.json").read_text())["settings"]["frames"] == 4



def test_a_play_at_another_frame_rate_says_it_replaces_that_report(tmp_path: Path,
                                                                    caplog: pytest.LogCaptureFixture) -> None:
    """The frame rate makes the camera path (its cameras speed / fps apart, its view turning turn_rate / fps a frame)
    as the seed and the frame count do: a run at --fps 30 into the folder of one at 60 replaced its report at the
    end without the warning that names what differs."""
    import logging

    from rtp.evaluate._play import _warn_of_another_report

    settings = {"scene": "procedural:0", "methods": ["jnyang"], "paths": ["fast"], "frames": 3, "fps": 60.0,
                "seed": 0, "size": [W, H], "tile_size": 16, "fail_metric": "jnyang", "fail_threshold": 0.25,
                "models": {}, "dynamic_resolution": None}
    (tmp_path / "play.json").write_text(json.dumps({"settings": settings}))
    with caplog.at_level(logging.WARNING, logger="rtp.evaluate"):
        _warn_of_another_report(tmp_path, settings)
        _warn_of_another_report(tmp_path, {**settings, "fps": 60})  # (the same rate, an int)
        assert "another run" not in caplog.text
        _warn_of_another_report(tmp_path, {**settings, "fps": 30.0})
    (warning,) = [r.getMessage() for r in caplog.records if "another run" in r.getMessage()]
    assert warning.startswith(f"{tmp_path} holds the report of another run (fps differ)")


def test_a_play_of_another_loop_setting_says_it_replaces_that_report(tmp_path: Path,
                                                                     caplog: pytest.LogCaptureFixture) -> None:
    """An --open-loop or --composite ablation, a run beside an engine's rates, without the sweep or with another
    --flip-every into the benchmark's folder replaced its report at the end without the warning (only the map,
    methods, paths, frames, ... were compared); a report that does not record such a setting (an older one) is not
    said to differ in it, and a report whose settings are not a mapping is "unreadable", not an AttributeError."""
    import logging

    from rtp.evaluate._play import _warn_of_another_report

    older = {"scene": "procedural:0", "methods": ["jnyang"], "paths": ["fast"], "frames": 3, "fps": 60.0,
             "seed": 0, "size": [W, H], "tile_size": 16, "fail_metric": "jnyang", "fail_threshold": 0.25,
             "models": {}, "dynamic_resolution": None}
    settings = {**older, "sweep": True, "flip_every": 20, "unseen_fraction": 0.5, "shading": "renderer",
                "history": "own displayed frame", "engine_rates": None}
    (tmp_path / "play.json").write_text(json.dumps({"settings": settings}))
    said = []
    for change in ({}, {"history": "full-rate frame (open loop)"}, {"shading": "composite"}, {"sweep": False},
                   {"engine_rates": {"image": "foveation", "combiner": "max"}}, {"flip_every": 0}):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="rtp.evaluate"):
            _warn_of_another_report(tmp_path, {**settings, **change})
        said.append([r.getMessage().split(": ")[0] for r in caplog.records if "another run" in r.getMessage()])
    assert said == [[]] + [[f"{tmp_path} holds the report of another run ({k} differ)"]
                           for k in ("history", "shading", "sweep", "engine_rates", "flip_every")]
    (tmp_path / "play.json").write_text(json.dumps({"settings": older}))  # (a report from before they were recorded)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtp.evaluate"):
        _warn_of_another_report(tmp_path, settings)
        assert "another run" not in caplog.text
        (tmp_path / "play.json").write_text(json.dumps({"settings": ["damaged"]}))
        _warn_of_another_report(tmp_path, settings)
    assert "another run (unreadable differ)" in caplog.text


def _stop_on_fast(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """rtp play's paths played in this process, Ctrl-C on the `fast` one (the `slow` one played to its end): the
    list of the paths begun, which each test's later runs append to."""
    from rtp.evaluate import _play

    played: list[str] = []
    real = _play._play_path

    def stopped_on_fast(job: dict[str, Any], *rest: Any) -> dict[str, Any]:
        played.append(job["path"])
        if job["path"] == "fast":
            raise KeyboardInterrupt
        return real(job, *rest)

    monkeypatch.setattr(_play, "_play_path", stopped_on_fast)
    return played


@pytest.mark.parametrize("workers", [1, 2])
def test_an_interrupted_play_resumes_without_playing_its_finished_paths_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, workers: int
) -> None:
    """`make play` is 15 minutes a map: a run stopped on its second path kept nothing. Each finished
    path is kept in the output folder until the report is written, and the same job resumes from it."""
    from rtp.evaluate import _play

    kw: dict[str, Any] = {"paths": ("slow", "fast"), "frames": 3, "size": (W, H), "sweep": False, "flip_every": 0,
                          "plots": False, "workers": workers}
    whole = play("procedural:0", "jnyang,yang2019", **kw)
    real = _play._play_path
    played = _stop_on_fast(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        play("procedural:0", "jnyang,yang2019", out=tmp_path, **{**kw, "workers": 1})
    assert played == ["slow", "fast"] and [f.name for f in tmp_path.iterdir()] == [".play-slow.partial.json"]

    monkeypatch.setattr(_play, "_play_path", lambda job, *rest: played.append(job["path"]) or real(job, *rest))
    ticks: list[int] = []
    resumed = play("procedural:0", "jnyang,yang2019", out=tmp_path, progress=ticks.append, **kw)
    assert played == ["slow", "fast", "fast"] and sum(ticks) == 6  # (one path left: played in this process)

    def timeless(rows: list[dict[str, Any]]) -> str:  # the choosing times differ from run to run
        return json.dumps([{k: v for k, v in r.items() if k != "predict_ms"} for r in rows])

    assert timeless(resumed.rows) == timeless(whole.rows) and resumed.unseen == whole.unseen
    assert not list(tmp_path.glob(".play-*")) and (tmp_path / "play.md").is_file()  # removed once the report is out

    if workers > 1:  # paths played in worker processes are kept as each ends, too
        kept: list[str] = []
        monkeypatch.setattr(_play, "_save_path", lambda outdir, pname, key, res: kept.append(pname))
        play("procedural:0", "jnyang,yang2019", out=tmp_path / "w", **kw)
        assert sorted(kept) == ["fast", "slow"]
    for kept_text in ("{", json.dumps({"key": "another job's settings", "result": {}})):  # damaged, or another job's
        (tmp_path / ".play-slow.partial.json").write_text(kept_text)
        played.clear()
        play("procedural:0", "jnyang,yang2019", out=tmp_path, **{**kw, "workers": 1, "paths": ("slow",)})
        assert played == ["slow"] and not list(tmp_path.glob(".play-*"))


def test_a_level_file_edited_between_runs_is_played_again(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A run on your own level, stopped on its second path, kept the first; the level edited (a texture
    repainted, a wall moved) and the run resumed, the first path's results came from the old level. The
    resume key holds a hash of what the file loads as, the files it references too."""
    from rtp.capture.scenes import procedural
    from rtp.evaluate import _play
    from rtp.plugins.pyrender import to_trimesh_scene

    level = tmp_path / "level.obj"
    to_trimesh_scene(procedural(2, rooms=(1, 1), texture_size=16)).export(level)
    out = tmp_path / "out"
    kw: dict[str, Any] = {"paths": ("slow", "fast"), "frames": 3, "size": (64, 48), "sweep": False, "flip_every": 0,
                          "plots": False, "workers": 1, "out": out}
    played = _stop_on_fast(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        play(str(level), "full", **kw)
    assert played == ["slow", "fast"] and (out / ".play-slow.partial.json").is_file()
    digest = _play._scene_digest(str(level), None)
    assert digest is not None and digest == _play._scene_digest(str(level), None)
    assert _play._scene_digest("procedural:2", None) is None
    # the texture the .mtl names repainted: the .obj's bytes are the same, the level is not
    texture = next(f for f in tmp_path.iterdir() if f.suffix == ".png")
    from PIL import Image

    img = np.asarray(Image.open(texture)).copy()
    img[..., :3] = 255 - img[..., :3]
    Image.fromarray(img).save(texture)
    assert _play._scene_digest(str(level), None) != digest
    played.clear()
    with pytest.raises(KeyboardInterrupt):
        play(str(level), "full", **kw)
    assert played == ["slow", "fast"]  # slow played again, on the repainted level


def test_an_interrupted_runs_temporary_files_are_removed_by_the_next(tmp_path: Path) -> None:
    """Ctrl-C (or SIGTERM) of `rtp play --workers 2` terminates the workers, in which no cleanup runs: one stopped
    while writing its path's GIF left `.play_slow.gif.XXXXXXXX.tmp`, and the rerun, its own GIF written within the
    minute after which a write takes another's temporary file for orphaned, left it beside its report. The
    next run into the folder removes the temporary files of rtp play's own outputs; no other file."""
    stale = [".play_slow.gif.ol0cwqt6.tmp", ".play_fast.png.a1b2c3d4.tmp", ".play.json.zz_9xk2m.tmp",
             ".play-slow.partial.json.q8w7e6r5.tmp", ".play_curves.png.abcdefgh.tmp"]
    others = [".notes.txt.abcdefgh.tmp", "play_slow.gif.abcdefgh.tmp", ".play_slow.gif.short.tmp", "mine.txt"]
    for name in stale + others:
        (tmp_path / name).write_bytes(b"half a file")
    play("procedural:0", "oracle", paths=("slow",), frames=3, size=(W, H), sweep=False, flip_every=0, plots=False,
         out=tmp_path)
    names = {f.name for f in tmp_path.iterdir()}
    assert not names & set(stale) and set(others) <= names and "play.json" in names


def test_a_path_ending_as_another_fails_in_its_worker_is_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """With --workers the paths end in worker processes, polled together: where one path failed (a GIF it could
    not write, a metric's error) in the same poll as the other ended, the error was raised first and the finished
    path's results were never kept, so the rerun played it again. The finished path is kept, then the error
    raised."""
    import concurrent.futures
    import contextlib
    import queue

    import rtp.capture
    from rtp.evaluate import _play

    class AtOnce:  # a pool that plays each path when it is submitted, in this process: both end before the poll
        def submit(self, fn: Any, work: Any, job: dict[str, Any]) -> concurrent.futures.Future[Any]:
            done: concurrent.futures.Future[Any] = concurrent.futures.Future()
            try:
                done.set_result(work(job, queue.Queue()))
            except Exception as err:  # (as a worker's error reaches the job)
                done.set_exception(err)
            return done

    monkeypatch.setattr(rtp.capture, "worker_pool", lambda workers, ticks=None: contextlib.nullcontext(AtOnce()))
    monkeypatch.setattr(rtp.capture, "tick_queue", queue.Queue)
    real = _play._play_path

    def slow_fails(job: dict[str, Any], *rest: Any) -> dict[str, Any]:
        if job["path"] == "slow":
            raise OSError("No space left on device")
        return real(job, *rest)

    monkeypatch.setattr(_play, "_play_path", slow_fails)
    with pytest.raises(OSError, match="No space left"):
        play("procedural:0", "jnyang", paths=("slow", "fast"), frames=3, size=(W, H), sweep=False, flip_every=0,
             plots=False, workers=2, out=tmp_path)
    assert [f.name for f in tmp_path.iterdir()] == [".play-fast.partial.json"]


def test_the_report_reads_the_worst_frames_off_each_sweep(tmp_path: Path) -> None:
    """bench/play_report.py --worst-frames: each method's worst 5% of frames' saving read off its sweep at 1 / 2 /
    5% failing tiles, as the matched saving is, the mean over the paths; '-' for a run from before the figure."""
    def run(name: str, with_p05: bool) -> str:
        settings = {"scene": name, "seed": 0, "frames": 3, "fps": 60, "size": [64, 48], "fail_metric": "jnyang",
                    "fail_threshold": 0.25, "methods": ["jnyang", "jnyang@1:b0.6", "oracle"]}
        sweep = {"jnyang": [(0.005, 0.40), (0.03, 0.50)], "jnyang@1:b0.6": [(0.01, 0.55), (0.04, 0.65)],
                 "oracle": [(0.0, 0.70)]}
        rows = [{"path": "fast", "method": m, "fail_share": f, "work_saved": w, "default": False,
                 **({"work_saved_p05": w} if with_p05 else {})} for m, pts in sweep.items() for f, w in pts]
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"settings": settings, "unseen": {"fast": [1.0, 0.01, 0.02]}, "matched": [],
                                    "rows": rows}))
        return str(path)

    out = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), run("a", True), run("b", True),
                          "--worst-frames"], capture_output=True, text=True, check=True).stdout
    # neither sweep fails 5% of the tiles: its reading there is a lower bound, ">=" as in play.md's table (it read as a
    # plain saving, and its mean as a plain mean); the oracle, not swept, is no bound
    assert "| a | 0 | fast | 42.0 / 46.0 / >= 50.0 | 55.0 / 58.3 / >= 65.0 | 70.0 |" in out
    assert "| mean | | | 42.0 / 46.0 / >= 50.0 | 55.0 / 58.3 / >= 65.0 | 70.0 |" in out
    assert ">=: a lower bound" in out
    old = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), run("c", False), "--worst-frames"],
                         capture_output=True, text=True, check=True).stdout
    assert "| c | 0 | fast | - | - | - |" in old


def test_the_report_summarises_reuse_over_paths_and_plots_it(tmp_path: Path) -> None:
    """bench/play_report.py over two maps: per reuse method the mean of the per-path ratios to the
    model at 1 / 2 / 5% failing tiles, the worst path at 5%, the paths >= 95% and the mean network
    work; --plot-reuse writes the picture."""
    runs = []
    for scene, base, reused, work in (("a", 0.50, (0.45, 0.47, 0.48), 0.25), ("b", 0.40, (0.36, 0.38, 0.39), 0.50)):
        settings = {"scene": scene, "seed": 0, "frames": 3, "fps": 60, "size": [64, 48], "fail_metric": "jnyang",
                    "fail_threshold": 0.25, "methods": ["jnyang", "jnyang@4"]}
        matched = [{"path": "fast", "method": "jnyang", "fail_share": lv, "work_saved": base} for lv in (0.01, 0.02, 0.05)]
        matched += [{"path": "fast", "method": "jnyang@4", "fail_share": lv, "work_saved": v}
                    for lv, v in zip((0.01, 0.02, 0.05), reused)]
        rows = [{"path": "fast", "method": "jnyang@4", "default": True, "network_frames": work}]
        path = tmp_path / f"{scene}.json"
        path.write_text(json.dumps({"settings": settings, "unseen": {"fast": [1.0, 0.01, 0.02]}, "matched": matched,
                                    "rows": rows}))
        runs.append(str(path))
    png = tmp_path / "reuse.png"
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), *runs, "--plot-reuse", str(png)],
                         capture_output=True, text=True, check=True).stdout
    # a: 90 / 94 / 96%, b: 90 / 95 / 97.5%; the worst at 5% is a's, both keep >= 95% there
    assert "| jnyang@4 | 2 | 37.5% | 90.0 / 94.5 / 96.8% | 96.0% (a fast) | 2 |" in out
    assert png.stat().st_size > 10_000
    # the mean over the paths, per method and level (results.md quoted means worked out by hand); no Yang 2019
    # played: no column of dashes for it
    assert "| mean | | | | | 45.0 / 45.0 / 45.0 | 40.5 / 42.5 / 43.5 |" in out
    assert "/ Yang" not in out and "not played" in out
    # a lower bound on one path (its sweep never failed that often) makes the mean one; none (never that rarely) none
    capped = json.loads(Path(runs[1]).read_text())
    capped["matched"][2]["capped"] = True
    capped["matched"][3]["work_saved"] = None  # (play.json writes nan as null)
    (tmp_path / "b-capped.json").write_text(json.dumps(capped))
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), runs[0], str(tmp_path / "b-capped.json")],
                         capture_output=True, text=True, check=True).stdout
    assert "| mean | | | | | 45.0 / 45.0 / >= 45.0 | - / 42.5 / 43.5 |" in out
    # a run of map a swept over other grids (the newer ones recorded in settings) is not merged with it
    newer = json.loads(Path(runs[0]).read_text())
    newer["settings"]["grids"] = {"model": [0.5, 1.0], "psnr_db": [0.0], "baseline": [1.0]}
    (tmp_path / "a-grids.json").write_text(json.dumps(newer))
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), runs[0], str(tmp_path / "a-grids.json")],
                         capture_output=True, text=True, check=True).stdout
    assert "a-grids.json was swept over other grids" in out
    assert out.count("| a | 0 | fast |") == 4  # two rows in each of the two tables
    # a run from before the grids were recorded is read off its rows' thresholds: the same grid merges, another not
    for values, merged in (((0.125, 0.25), True), ((0.0625, 0.25), False)):
        older = json.loads(Path(runs[0]).read_text())
        older["settings"]["methods"] = ["jnyang@2"]
        older["rows"] = [{"path": "fast", "method": "jnyang@2", "default": v == 0.25, "value": v, "network_frames": 0.5}
                         for v in values]
        older["matched"] = [{"path": "fast", "method": "jnyang@2", "fail_share": lv, "work_saved": 0.49}
                            for lv in (0.01, 0.02, 0.05)]
        (tmp_path / "a-old.json").write_text(json.dumps(older))
        out = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), str(tmp_path / "a-grids.json"),
                              str(tmp_path / "a-old.json")], capture_output=True, text=True, check=True).stdout
        assert ("swept over other grids" not in out) == merged
        assert out.count("| a | 0 | fast |") == (2 if merged else 4)


def _report_run(folder: Path, scene: str, *, reuse_work: float | None = 0.25, reused: bool = True,
                **settings: Any) -> str:
    """A play.json of one path for bench/play_report.py: jnyang (and jnyang@4, its network's work ``reuse_work``
    where ``reused``), ``settings`` over the defaults (3 frames at 60 Hz, 64x48, jnyang over 0.25, 16-pixel tiles)."""
    methods = ["jnyang", "jnyang@4"] if reused else ["jnyang"]
    s = {"scene": scene, "seed": 0, "frames": 3, "fps": 60, "size": [64, 48], "fail_metric": "jnyang",
         "fail_threshold": 0.25, "methods": methods, **settings}
    matched = [{"path": "fast", "method": m, "fail_share": lv, "work_saved": 0.5 if m == "jnyang" else 0.45}
               for m in methods for lv in (0.01, 0.02, 0.05)]
    rows = [{"path": "fast", "method": "jnyang@4", "default": True, "fail_share": 0.02, "work_saved": 0.45,
             "network_frames": reuse_work}] if reused else []
    path = folder / f"{scene}-{len(list(folder.glob('*.json')))}.json"
    path.write_text(json.dumps({"settings": s, "unseen": {"fast": [1.0] + [0.01] * (s["frames"] - 1)},
                                "matched": matched, "rows": rows,
                                "frames": {"fast": {m: {"saved": [0.5] * s["frames"], "fail": [0.01] * s["frames"]}
                                                    for m in methods}}}))
    return str(path)


def _play_report(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), *args], capture_output=True, text=True,
                          timeout=120)


def test_the_report_refuses_runs_of_other_settings_before_any_table(tmp_path: Path) -> None:
    """Runs of other frames, size, frame rate or failure rule were printed under the first run's header and
    averaged in its mean rows (an 8- and a 6-frame run: a --window row shorter than its header): refused in one
    line naming the setting and the files, nothing printed. Other tile sizes share the tables, a mean each."""
    for key, value, said in (("frames", 6, "frames: 8 ({a}) against 6 ({b})"),
                             ("size", [160, 96], "size: 64x48 ({a}) against 160x96 ({b})"),
                             ("fps", 30, "frame rate: 60 Hz ({a}) against 30 Hz ({b})"),
                             ("fail_metric", "flip", "fail metric: jnyang ({a}) against flip ({b})"),
                             ("fail_threshold", 0.5, "fail threshold: 0.25 ({a}) against 0.5 ({b})")):
        folder = tmp_path / key
        folder.mkdir()
        a = _report_run(folder, "a", frames=8)
        b = _report_run(folder, "b", **{"frames": 8, key: value})
        run = _play_report(a, b, "--window", "3")
        assert run.returncode == 2 and run.stdout == "", (key, run.stdout)
        assert run.stderr.strip() == ("play_report.py: error: the runs differ in " + said.format(a=a, b=b)
                                      + "; one table reads runs of one setting: report them apart"), run.stderr
    # two tile sizes, two maps each: every row says its tiles, and each size has its own mean (not one of both)
    folder = tmp_path / "tiles"
    folder.mkdir()
    runs = [_report_run(folder, m, tile_size=t) for t in (16, 8) for m in ("a", "b")]
    out = subprocess.run([sys.executable, str(ROOT / "bench" / "play_report.py"), *runs, "--worst-frames"],
                         capture_output=True, text=True, check=True, timeout=120).stdout
    assert "| a (8px) | 0 | fast |" in out and "| b (16px) | 0 | fast |" in out
    assert out.count("| mean (16px) |") == out.count("| mean (8px) |") == 2 and "| mean |" not in out
    assert "| jnyang@4 (16px) | 2 |" in out and "| jnyang@4 (8px) | 2 |" in out


def _paths_run(folder: Path, name: str, paths: dict[str, list[str]], reuse: dict[str, Any] | None = None) -> str:
    """A play.json of map ``a`` (4 frames) with ``paths``: path -> its methods, each method's saving a number of its
    own (``0.1 * (index of the path + 1) + 0.01 * index of the method``), so that a table cell says where it is from."""
    methods = list(dict.fromkeys(m for ms in paths.values() for m in ms))
    saving = {(p, m): round(0.1 * (i + 1) + 0.01 * methods.index(m), 4) for i, p in enumerate(paths) for m in paths[p]}
    s = {"scene": "a", "seed": 0, "frames": 4, "fps": 60, "size": [64, 48], "fail_metric": "jnyang",
         "fail_threshold": 0.25, "methods": methods, "paths": list(paths), "reuse": reuse or {},
         "cameras": {p: {"length_m": 1.0, "eye_height_m": 1.5 + i / 10} for i, p in enumerate(paths)}}
    matched = [{"path": p, "method": m, "fail_share": lv, "work_saved": saving[p, m]}
               for p, ms in paths.items() for m in ms for lv in (0.01, 0.02, 0.05)]
    frames = {p: {m: {"saved": [saving[p, m]] * 4, "fail": [0.01 * (k % 2) for k in range(4)]} for m in ms}
              for p, ms in paths.items()}
    out = folder / f"{name}.json"
    out.write_text(json.dumps({"settings": s, "unseen": {p: [1.0, 0.01, 0.02, 0.03] for p in paths},
                               "matched": matched, "rows": [], "frames": frames}))
    return str(out)


def test_the_report_merges_runs_of_other_paths(tmp_path: Path) -> None:
    """Runs of one map merge into one row per path: a run of the fast path beside one of the slow path was dropped
    whole (its path, its methods, its windows), and a method a second run added on one path only showed "-" on the
    other where it had not played (blank, as a method a run did not play). --by-age leaves out a reuse method with a
    refresh share (:rS), whose network runs early and restarts the interval: ages by frame index were wrong."""
    slow = _paths_run(tmp_path, "slow", {"slow": ["jnyang"]})
    fast = _paths_run(tmp_path, "fast", {"fast": ["jnyang", "jnyang@2", "jnyang@2:r0.05"]},
                      {"jnyang@2": {"k": 2, "unseen": "full", "refresh": None},
                       "jnyang@2:r0.05": {"k": 2, "unseen": "full", "refresh": 0.05}})
    out = _play_report(slow, fast, "--window", "2", "--by-age", "--reuse", "jnyang@2")
    assert out.returncode == 0, out.stderr
    text = out.stdout
    assert "| map | seed | path | eye (m) | unseen % mean / max | jnyang | jnyang@2 | jnyang@2:r0.05 |" in text
    assert "| a | 0 | slow | 1.50 | 2.00 / 3.00 | 10.0 / 10.0 / 10.0 |  |  |" in text, text
    assert "| a | 0 | fast | 1.50 | 2.00 / 3.00 | 10.0 / 10.0 / 10.0 | 11.0 / 11.0 / 11.0 | 12.0 / 12.0 / 12.0 |" in text
    assert "| a | 0 | fast | jnyang@2 | 11.0 / 0.5 | 11.0 / 1.0 |" in text  # (its windows: frames 1-2, 3)
    age = text[text.index("by frames since"):]
    assert "| a | 0 | fast | jnyang@2 | 11.0 / 0.0 | 11.0 / 1.0 |" in age  # age 0: frame 2; age 1: frames 1, 3
    assert "jnyang@2:r0.05" not in age
    # a model file whose name holds an "@" (taken whole, evaluation.md "Methods"): the method without reuse beside it
    # is that file, not the name cut at its first "@" (the row of the same frames was missing)
    at = _paths_run(tmp_path, "at", {"fast": ["m@v2.onnx", "m@v2.onnx@2"]},
                    {"m@v2.onnx@2": {"k": 2, "unseen": "full", "refresh": None}})
    age = _play_report(at, "--by-age", "--model", "m@v2.onnx").stdout
    assert "| a | 0 | fast | m@v2.onnx@2 | 11.0 / 0.0 | 11.0 / 1.0 |" in age, age
    assert "| a | 0 | fast | m@v2.onnx (same frames) | 10.0 / 0.0 | 10.0 / 1.0 |" in age, age
    # a second run adding a method on one of the first run's paths: the other path's cell blank, not "-"
    both = _paths_run(tmp_path, "both", {"slow": ["jnyang"], "fast": ["jnyang"]})
    more = _paths_run(tmp_path, "more", {"fast": ["jnyang", "jnyang@2"]})
    text = _play_report(both, more).stdout
    assert "| a | 0 | slow | 1.50 | 2.00 / 3.00 | 10.0 / 10.0 / 10.0 |  |" in text, text
    assert "| a | 0 | fast | 1.60 | 2.00 / 3.00 | 20.0 / 20.0 / 20.0 | 11.0 / 11.0 / 11.0 |" in text, text


def test_plot_reuse_is_refused_where_there_is_nothing_to_plot(tmp_path: Path) -> None:
    """--plot-reuse wrote an empty plot (matplotlib's "No artists with labels") where no reuse method could be
    drawn: refused in one line before any table; the reuse summary says "-" once, not "- / - / -%"."""
    png = tmp_path / "reuse.png"
    plain = [_report_run(tmp_path, m, reused=False) for m in ("a", "b")]
    unrecorded = [_report_run(tmp_path, m, reuse_work=None) for m in ("c", "d")]
    for runs, extra, words in (
            (plain, [], "--plot-reuse: the runs played no reuse method of jnyang@4 (--reuse names them): nothing to plot"),
            (plain, ["--model", "psnr"], "--plot-reuse: the runs did not play psnr (--model)"),
            (unrecorded, [], "--plot-reuse: no path of jnyang@4 has both a readable share of jnyang's saving at 5% "
                             "failing tiles and the network's work per frame")):
        run = _play_report(*runs, *extra, "--plot-reuse", str(png))
        assert run.returncode == 2 and run.stdout == "" and "Traceback" not in run.stderr, run.stderr
        assert run.stderr.strip().startswith(f"play_report.py: error: {words}"), run.stderr
        assert not png.exists()
    # no readable kept share on any path: one dash in the summary
    capped = json.loads(Path(unrecorded[0]).read_text())
    for m in capped["matched"]:
        m["capped"] = True
    Path(unrecorded[0]).write_text(json.dumps(capped))
    for path in unrecorded[1:]:
        other = json.loads(Path(path).read_text())
        other["matched"] = [{**m, "work_saved": None} if m["method"] == "jnyang@4" else m for m in other["matched"]]
        Path(path).write_text(json.dumps(other))
    out = _play_report(*unrecorded).stdout
    assert "| jnyang@4 | 2 | - | - | - | 0 |" in out, out


def test_a_second_play_into_a_folder_being_played_into_is_refused(tmp_path: Path) -> None:
    """Two closed loops into one --out read each other's kept paths and wrote their files among each
    other's; the second is now refused naming the first, and the folder's lock goes with the run."""
    import os

    from rtp.sdk.files import LOCK_NAME, writer_lock

    out = tmp_path / "play"
    out.mkdir()
    with writer_lock(out, "rtp play", RuntimeError):
        with pytest.raises(PlayError, match=rf"^out: {out} is being written by another job \(rtp play, pid "
                                            rf"{os.getpid()}\): wait for it to end, or play into another folder$") as e:
            play("procedural:0", "oracle", paths=("fast",), frames=3, size=(64, 48), sweep=False, plots=False, out=str(out))
        assert e.value.name == "out"
    play("procedural:0", "oracle", paths=("fast",), frames=3, size=(64, 48), sweep=False, plots=False, out=str(out))
    assert (out / "play.md").is_file() and not (out / LOCK_NAME).exists()


def test_a_gif_frame_labels_its_place_and_keys_the_rate_colours_in_its_spare_cell() -> None:
    """Each GIF frame's reference panel says which frame it is; with a cell of the three-column grid
    to spare, the colour key fills it at the panels' size (every class's colour at full strength
    there); without one, the first overlay carries the overlay's small key. Labels are drawn after the
    downscale, so they are as tall at 1280x720 as at the panel's own size."""
    from rtp.evaluate._play import _ANIM_PANEL_WIDTH, _anim_frame
    from rtp.evaluate.plots import rate_legend

    h, w = 225, _ANIM_PANEL_WIDTH

    def frame(n: int, scale: float = 1) -> np.ndarray:
        ref = np.full((round(h * scale), round(w * scale), 3), 0.5, np.float32)
        rates = np.full((-(-ref.shape[0] // 16), -(-ref.shape[1] // 16)), sdk.RATE_CODES["2x2"], np.uint8)
        return _anim_frame(ref, {f"m{i}": (ref, rates) for i in range(n)}, 16, "frame 7 of 30, 0.12 s")

    def has(img: np.ndarray, rgb: tuple[float, float, float]) -> bool:
        return bool((np.abs(img.astype(int) - np.round(np.array(rgb) * 255)).max(-1) <= 2).any())

    spare = frame(4)  # five panels: one cell to spare
    assert spare.shape == (2 * h, 3 * w, 3)
    key = spare[h:, 2 * w:]
    assert all(has(key, colour) for _, colour in rate_legend()[1:]) and not has(spare[:h], rate_legend()[3][1])
    full = frame(5)  # six panels: none to spare, and no key cell
    assert full.shape == (2 * h, 3 * w, 3) and not has(full[h:, 2 * w:], rate_legend()[1][1])
    # the first overlay's own key (dark box, bottom-left) only where no cell is spare
    assert full[h - 3:h, w:w + 10].mean() < spare[h - 3:h, w:w + 10].mean()
    # the label's black box is as tall on a 640x360 frame, downscaled, as on the panel-sized one
    large = frame(4, scale=1.6)
    assert large.shape == spare.shape

    def box_height(img: np.ndarray) -> int:
        column = img[:, 1]
        return int(np.argmax(column.max(-1) > 0))

    assert box_height(spare) == box_height(large) >= 14


def test_a_gif_label_wider_than_its_panel_wraps_inside_it() -> None:
    """On a panel under 300 pixels wide (rtp play --size 160x96) the reference's label ran off it: "full rate
    (reference), frame 75 of 150, 1.25 s" read "full rate (reference), frame 7". It wraps after its commas now, and a
    single word too wide (a long method name) is drawn smaller, every line inside the panel."""
    from rtp.evaluate._play import _label

    grey = np.full((96, 160, 3), 128, np.uint8)
    one = _label(np.full((96, 400, 3), 128, np.uint8), "full rate (reference), frame 75 of 150, 1.25 s")
    wrapped = _label(grey, "full rate (reference), frame 75 of 150, 1.25 s")

    def box(img: np.ndarray) -> tuple[int, int]:  # (the black box's height and width, from its top-left corner)
        black = (img == 0).all(-1)
        return int(np.argmin(black[:, 0])), int(np.argmin(black[0])) if not black[0].all() else img.shape[1]

    (h1, w1), (h2, w2) = box(one), box(wrapped)
    assert w1 < 400 and w2 < 160 - 2 and h2 > h1 + 10  # (two lines, inside the panel)
    long = _label(grey, "m" * 60)
    assert box(long)[1] < 160 - 2


def test_rtp_models_play_on_finer_and_coarser_hardware_tiles(tmp_path: Path) -> None:
    """--tile-size 8 under 16-pixel models (AMD's and Intel's VRS tiles): each hardware tile takes its
    model tile's rate, so the shading (and every frame after it) is the 16-pixel run's, to the last
    bit, while the failing share is judged per 8-pixel tile (never more than per 16-pixel tile: a
    quarter of a tile is never worse than the tile for JNYang) and the baselines decide per 8 pixels.
    Coarser run tiles than a model's (an 8-pixel model on NVIDIA's 16) decide on the worst estimate of
    the model tiles each covers, as ``sdk.load(tile_size=16)`` does; tiles that neither divide nor are
    divided by the model's are refused."""
    runs = {t: play("procedural:0", "jnyang,jnyang@2,fidelityfx", paths=("fast",), frames=4, size=(96, 64),
                    sweep=False, flip_every=0, tile_size=t, out=tmp_path / str(t), plots=False)
            for t in (16, 8)}
    for method in ("jnyang", "jnyang@2"):
        coarse, fine = (runs[t].frames["fast"][method] for t in (16, 8))
        assert fine["saved"] == coarse["saved"], method
        assert all(f <= c for f, c in zip(fine["fail"], coarse["fail"])), method
    assert runs[8].frames["fast"]["fidelityfx"]["saved"] != runs[16].frames["fast"]["fidelityfx"]["saved"]
    # on the first frame (no history yet: the same inputs in both runs) a 16-pixel tile takes a rate that
    # passes on each of its four 8-pixel tiles, each of which alone took that rate or a coarser one
    reports = {t: play("procedural:0", "jnyang-8px", paths=("fast",), frames=3, size=(96, 64), sweep=False,
                       flip_every=0, tile_size=t, plots=False) for t in (8, 16)}
    eight = {t: r.frames["fast"]["jnyang-8px"] for t, r in reports.items()}
    assert eight[16]["saved"][0] < eight[8]["saved"][0]
    # play.md says which models ran on tiles other than their own, and how (the header named only the run's tiles)
    assert "Models on tiles other than their own: jnyang-8px (8px: each 16px tile decides on the worst of the 4 model " \
           "tiles it covers)." in reports[16].to_markdown()
    assert "other than their own" not in reports[8].to_markdown()
    assert "jnyang (16px: each 8px tile takes the rate of the model tile it lies in)" in runs[8].to_markdown()
    assert play("procedural:0", "jnyang", paths=("fast",), frames=3, size=(96, 64), sweep=False, flip_every=0,
                tile_size=32, plots=False).frames["fast"]["jnyang"]["saved"][0] <= runs[16].frames["fast"]["jnyang"]["saved"][0]
    with pytest.raises(PlayError, match=r"the model uses 8px tiles, the run 12px"):
        play("procedural:0", "jnyang-8px", paths=("fast",), frames=3, size=(96, 64), sweep=False, tile_size=12)


def test_beside_an_engines_own_rates(tmp_path: Path) -> None:
    """``engine_rates=``: every method's rates meet the engine's in the combiner; full's row is the engine's rates
    alone (it saves, and fails nowhere beyond them), the aware oracle never fails beyond the engine's rate, a budget
    counts the engine's saving, and ``:alone`` chooses without them. Bad engine images, combiners and ``:alone``
    without an engine are refused before anything runs."""
    from rtp.evaluate import foveation_rates

    assert parse_methods("jnyang@1:alone")[0].alone and not parse_methods("jnyang")[0].alone
    rep = play("procedural:0", "full,oracle,jnyang,jnyang@1:alone,jnyang@1:b0.8", paths=("fast",), frames=5,
               size=(W, H), sweep=False, flip_every=0, plots=False, engine_rates="foveation", combiner="max")
    assert rep.settings["engine_rates"] == {"image": "foveation", "combiner": "max"}
    rows = {r["method"]: r for r in rep.rows}
    fovea = sdk.work_saved(foveation_rates(*sdk.tile_grid(H, W, 16)), (H, W), 16)
    assert rows["full"]["work_saved"] == pytest.approx(fovea) and rows["full"]["fail_share"] == 0.0
    assert rows["oracle"]["fail_share"] == 0.0 and rows["oracle"]["work_saved"] > fovea
    step = sdk.MAX_SAVING * 16 * 16 / (W * H)  # (one tile's whole saving: the budget overshoots by less)
    assert all(0.8 - 1e-9 <= s <= 0.8 + step for s in rep.frames["fast"]["jnyang@1:b0.8"]["saved"][1:])
    assert all(rows[m]["work_saved"] >= fovea - 1e-9 for m in ("jnyang", "jnyang@1:alone"))
    assert "The engine's own rates (foveation, rtp.evaluate.engine_rates) meet every method's" in rep.to_markdown()
    # motion-blur rates are anisotropic: combined by max, a rate of the oracle's own and one of the engine's can
    # make one neither judged; the oracle beside them never fails beyond the engine's rate
    moving = play("procedural:0", "oracle", paths=("fast",), frames=6, size=(W, H), sweep=False, flip_every=0,
                  plots=False, engine_rates="motion")
    assert moving.rows[0]["fail_share"] == 0.0 and moving.rows[0]["work_saved"] > 0.5
    for kw, words in (({"engine_rates": "vr"}, "engine_rates: expected one of foveation, motion"),
                      ({"engine_rates": "motion", "combiner": "avg"}, "combiner: expected one of min, max, sum"),
                      ({}, "':alone' chooses without the engine's own rates")):
        with pytest.raises(PlayError, match=words):
            play("procedural:0", "jnyang@1:alone", paths=("fast",), frames=3, size=(W, H), sweep=False,
                 flip_every=0, plots=False, out=tmp_path / "never", **kw)
    assert not (tmp_path / "never").exists()


def test_a_failure_drawing_the_figures_leaves_the_previous_report_whole(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """play.md and play.json were written before the figures were drawn: a failure drawing them left this run's
    report beside the previous run's figures. Everything is drawn before the first file is written."""
    from rtp.evaluate import _play, plots

    rep = play("procedural:0", "full", paths=("slow",), frames=3, size=(64, 48), sweep=False, flip_every=0,
               plots=False)
    names = ("play.md", "play.json", "play_curves.png", "play_frames.png")
    for name in names:
        (tmp_path / name).write_bytes(b"the previous run's " + name.encode())

    def broken(report: Any) -> Any:
        raise RuntimeError("drawing failed")

    monkeypatch.setattr(plots, "play_frames", broken)
    with pytest.raises(RuntimeError, match="drawing failed"):
        _play._write(rep, tmp_path, True)
    assert all((tmp_path / n).read_bytes() == b"the previous run's " + n.encode() for n in names)
    monkeypatch.undo()
    assert _play._write(rep, tmp_path, True) == list(names)


def test_a_path_player_whose_scene_fails_to_load_releases_its_renderer(monkeypatch: pytest.MonkeyPatch) -> None:
    """A PathPlayer that made its own renderer and then failed to load the scene kept the renderer (its GL context
    and render targets) for the garbage collector: the caller never got the player to close."""
    from rtp.plugins.moderngl import Renderer, RendererError

    released = []

    def refuse(self: Any, scene: Any) -> None:
        raise RendererError("mesh 0: material 3 not in 0..0")

    release = Renderer.release
    monkeypatch.setattr(Renderer, "load_scene", refuse)
    monkeypatch.setattr(Renderer, "release", lambda self: (released.append(self), release(self))[-1])
    sc, _ = load_scene("procedural:0", None, None, None)
    with pytest.raises(RendererError, match="material 3"):
        PathPlayer(sc, (32, 24))
    assert len(released) == 1


def test_the_report_notes_runs_merged_across_loop_settings(tmp_path: Path) -> None:
    """The merge key names the map, seed, frames, size, failing rule and tiles, not the loop's settings: an open-loop
    run (history: the full-rate frame) merged with a closed one in silence. Still merged (runs before a setting was
    recorded must), now with a note naming the setting and both values; runs that agree get none."""
    closed = _paths_run(tmp_path, "closed", {"slow": ["jnyang"]})
    opened = _paths_run(tmp_path, "open", {"slow": ["jnyang", "jnyang@2"]})
    for path, history in ((closed, "own displayed frame"), (opened, "full-rate frame (open loop)")):
        rep = json.loads(Path(path).read_text())
        rep["settings"]["history"] = history
        Path(path).write_text(json.dumps(rep))
    out = _play_report(closed, opened)
    assert out.returncode == 0, out.stderr
    assert (f"note: {opened} was played with another history than a run of the same map before it (history: "
            "'own displayed frame' and 'full-rate frame (open loop)')") in out.stdout + out.stderr
    agree = _paths_run(tmp_path, "agree", {"slow": ["jnyang", "jnyang@2"]})
    assert "was played with another" not in _play_report(closed, agree).stdout


def test_a_mesh_files_warnings_are_said_once_by_a_closed_loop(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """``rtp play`` reads a mesh file in its check before the run and again for the path it plays: each of the
    file's warnings (a texture it cannot read) was said twice, as ``rtp capture``'s were."""
    import logging

    from rtp.capture.scenes import procedural
    from rtp.plugins.pyrender import to_trimesh_scene

    level = tmp_path / "level.obj"
    to_trimesh_scene(procedural(2, rooms=(1, 1), texture_size=16)).export(level)
    (tmp_path / "crate.png").unlink()
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        play(str(level), "full", paths=("slow",), frames=3, size=(64, 48), sweep=False, flip_every=0, plots=False)
    said = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING and "crate.png" in r.getMessage()]
    assert len(said) == 1, said
