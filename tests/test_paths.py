"""Camera paths for the closed-loop benchmark: deterministic, valid, at the profile's pace."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rtp.capture import load_scene
from rtp.capture.paths import PATH_PROFILES, camera_path, frame_unseen_share, unseen_shares
from rtp.capture.viewpoints import ViewpointError, _Validator, free_space, scene_triangles


@pytest.fixture(scope="module")
def scene():  # noqa: ANN201
    return load_scene("procedural:0", None, None, None)


@pytest.mark.parametrize("profile", ["slow", "fast"])
def test_paths_are_deterministic_valid_and_paced(scene, profile: str) -> None:  # noqa: ANN001
    sc, blockers = scene
    path = camera_path(sc, 90, profile, seed=3, blockers=blockers)
    assert len(path) == 90 and path.fps == 60 and path.profile == profile
    assert path.cameras == camera_path(sc, 90, profile, seed=3, blockers=blockers).cameras
    assert path.cameras != camera_path(sc, 90, profile, seed=4, blockers=blockers).cameras
    prof = PATH_PROFILES[profile]
    pos = np.array([c.position for c in path.cameras])
    steps = np.linalg.norm(np.diff(pos, axis=0), axis=1)
    assert np.all(steps <= prof.speed / 60 * 1.01)  # never faster than the profile
    assert path.length() > 0.8 * prof.speed * 89 / 60  # and not much slower (the path bends)
    _, grid, reach, _ = free_space(sc, blockers=blockers)
    val = _Validator(scene_triangles(sc))
    for a, b in zip(pos[:-1], pos[1:]):
        assert reach[tuple(grid.index(b))] and val.clearance(b, 0.25) and val.segment_clear(a, b)
    yaw = np.array([c.yaw for c in path.cameras])
    turn = np.abs((np.diff(yaw) + 180) % 360 - 180)
    sway_rate = 2 * math.pi * prof.sway / prof.sway_period / 60  # the sway's own turning, per frame
    assert turn.max() <= prof.turn_rate / 60 + sway_rate + 1e-6


@pytest.mark.gl
def test_fast_paths_uncover_more_of_each_frame(scene) -> None:  # noqa: ANN001
    sc, blockers = scene
    slow = unseen_shares(camera_path(sc, 24, "slow", seed=1, blockers=blockers), sc, (96, 64))
    fast = unseen_shares(camera_path(sc, 24, "fast", seed=1, blockers=blockers), sc, (96, 64))
    assert slow[0] == fast[0] == 1.0  # the first frame has no history
    assert 0 <= slow[1:].mean() < fast[1:].mean() < 0.5


@pytest.mark.gl
def test_bench_paths_prints_a_row_a_path_and_counts_the_frames_on_stderr() -> None:
    """bench/paths.py: a row per map and path, the unseen shares of unseen_shares; a progress bar of the frames
    rendered on stderr (a 300-frame run of the test maps was minutes of silence)."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    run = subprocess.run([sys.executable, str(root / "bench" / "paths.py"), "--maps", "procedural:0", "--frames", "3",
                          "--size", "64x48"], cwd=root, capture_output=True, text=True, timeout=300, check=True)
    rows = [line for line in run.stdout.splitlines() if line.startswith("| procedural:0 |")]
    assert [r.split("|")[2].strip() for r in rows] == list(PATH_PROFILES)
    assert "rendering" in run.stderr and "6/6" in run.stderr  # 3 frames of 2 paths


def test_the_unseen_share_counts_every_pixel_sky_included() -> None:
    """A frame looking over a level's edge is mostly sky that the previous frame showed too (sky is
    seen when it was sky before): a few new pixels of geometry are a few pixels, not 100%."""
    seen = np.ones((72, 128), np.float32)
    seen[:3, :3] = 0.0  # the only geometry in view, all of it new
    assert frame_unseen_share(seen) == pytest.approx(9 / (72 * 128))
    assert frame_unseen_share(np.zeros((4, 4))) == 1.0 and frame_unseen_share(np.ones((4, 4))) == 0.0


def test_bad_path_requests_are_refused(scene) -> None:  # noqa: ANN001
    sc, _ = scene
    with pytest.raises(ViewpointError, match="unknown path profile 'jog'"):
        camera_path(sc, 10, "jog")
    for kwargs, words in (({"frames": 0}, "frames: expected an integer >= 1"), ({"frames": 2.5}, "frames"),
                          ({"seed": -1}, "seed: expected an integer >= 0"), ({"fps": float("nan")}, "fps"),
                          ({"fov_y": 180}, "fov_y"), ({"clearance": -1}, "clearance"), ({"voxel": 0}, "voxel"),
                          ({"max_height": float("inf")}, "max_height"),
                          ({"frames": 36_001}, r"^frames: expected at most 36000 \(ten minutes at 60 frames a second\)"),
                          ({"fps": 1e-10}, r"^fps: 10 frames at 1e-10 frames a second last 90,000,000,000 s; expected"),
                          ({"clearance": 5.0}, r"^no free space in 'procedural-\d+' at 5.0 m from the geometry")):
        with pytest.raises(ViewpointError, match=words):  # (seed -1 was numpy's ValueError, fps nan accepted)
            camera_path(sc, **{"frames": 10, **kwargs})  # type: ignore[arg-type]
    # running at one frame a second: cameras 6 m apart, which no smoothing keeps clear of the walls
    with pytest.raises(ViewpointError, match=r"could not be smoothed into valid cameras \(6 m between frames at 1 frames "
                                             r"a second: at a higher rate they are closer\)$"):
        camera_path(sc, 100, "fast", fps=1.0)


def test_paths_walk_the_floors_at_the_spawn_points_eye_height(scene) -> None:  # noqa: ANN001
    """A player's eye, not a free-floating camera: each camera stands over a floor at the eye height
    the scene's spawn points give (the procedural rooms spawn at 1.6 m), steps included."""
    from rtp.capture.viewpoints import _Floors

    sc, blockers = scene
    _, grid, _, _ = free_space(sc, blockers=blockers)
    floors = _Floors(grid)
    for profile, seed in (("slow", 0), ("fast", 1)):
        path = camera_path(sc, 120, profile, seed=seed, blockers=blockers)
        assert abs(path.eye_height - 1.6) <= grid.voxel / 2 + 1e-6
        over = np.array([c.position[1] - floors.below(np.array(c.position)) for c in path.cameras])
        assert np.median(over) == pytest.approx(path.eye_height, abs=1e-6)
        assert np.all(np.abs(over - path.eye_height) <= 0.6 + 1e-6)  # a step, smoothed, at most
    own = camera_path(sc, 60, "slow", seed=0, blockers=blockers, eye_height=1.0)
    assert own.eye_height == 1.0
    assert np.median([c.position[1] - floors.below(np.array(c.position)) for c in own.cameras]) == pytest.approx(1.0)
    with pytest.raises(ViewpointError, match="eye_height"):
        camera_path(sc, 10, eye_height=-1.0)


def test_a_far_backdrop_does_not_coarsen_the_paths_floors(scene) -> None:  # noqa: ANN001
    """A map whose drawn geometry spans far more than its arena (oa_dm3: a 560 m backdrop around a
    75 m arena) gets a coarse whole-map grid; the paths voxelise again around the playable part and
    still walk its floors at the eye height."""
    import dataclasses

    from rtp.scene import Mesh

    sc, blockers = scene
    far = np.array([[-1500, -200, -1500], [1500, -200, -1500], [0, 800, 1500]], np.float32)  # a 3 km backdrop
    backdrop = Mesh(far, np.tile([0, 0, 1], (3, 1)).astype(np.float32), np.zeros((3, 2), np.float32),
                    np.array([[0, 1, 2]], np.uint32), 0)
    big = dataclasses.replace(sc, meshes=[*sc.meshes, backdrop])
    _, coarse, _, _ = free_space(big, blockers=blockers)
    _, fine, reach, cand = free_space(big, blockers=blockers, focus=True)
    assert coarse.voxel > 1.0 and fine.voxel == 0.25 and cand.any()
    _, plain, _, plain_cand = free_space(sc, blockers=blockers)
    centres = plain.centre(np.flatnonzero(plain_cand))  # the arena's free space (away from walls), found again
    assert reach[tuple(fine.index(centres).T)].mean() > 0.98
    path = camera_path(big, 60, "slow", seed=0, blockers=blockers)
    assert abs(path.eye_height - 1.6) <= 0.125


def _room(side: float):  # noqa: ANN202
    """A closed ``side`` x 3 x ``side`` m room with one spawn point at its centre."""
    from rtp.capture.scenes._geometry import MeshBuilder
    from rtp.scene import Material, Scene, SpawnPoint

    b = MeshBuilder()
    b.box(0, (-side / 2, 0, -side / 2), (side / 2, 3, side / 2))
    return Scene(f"room-{side:g}", b.meshes(), [Material("m")], spawn_points=[SpawnPoint((0.0, 1.6, 0.0))])


def test_paths_keep_moving_to_their_last_frame() -> None:
    """The walker's metres are counted before smoothing; a walk that bends, or paces to and fro in a pocket of
    the domain, smooths into a shorter path, and the camera stood still for the frames past its end (a slow
    path of 150 frames on procedural:3, seed 10, stood for its last 91 frames; a fast one of 300 frames in a
    4 m room for 19). Every frame now moves at the profile's speed, and a domain too small for the path is a
    ViewpointError that says so, not a camera standing still."""
    sc, blockers = load_scene("procedural:3", None, None, None)
    for where, path in (("procedural:3", camera_path(sc, 150, "slow", seed=10, blockers=blockers)),
                        ("room", camera_path(_room(4.0), 300, "fast", seed=0))):
        prof = PATH_PROFILES[path.profile]
        steps = np.linalg.norm(np.diff([c.position for c in path.cameras], axis=0), axis=1)
        assert steps.min() > 0.25 * prof.speed / 60, where  # (a chord of a sharp bend is shorter than the arc)
        assert path.length() > 0.95 * prof.speed * (len(path) - 1) / 60, where
    with pytest.raises(ViewpointError, match=r"^no camera path of 7.5 m \(300 frames at 1.5 m/s and 60 frames a second\) "
                                             r"found in 'room-2.5' \(profile slow\) in 20 tries: the longest smoothed "
                                             r"walk covered \d+\.\d m, pacing to and fro; expected a viewpoint domain"):
        camera_path(_room(2.5), 300, "slow", seed=0)


def test_custom_path_profiles_are_checked(scene) -> None:  # noqa: ANN001
    """A PathProfile's numbers are checked as a MotionProfile's are: speed 0 or a sway period of 0 made nan yaws
    (Camera's error, naming no profile), a negative speed stood the camera still at its start, a negative turn
    rate turned it the wrong way, and an infinite speed walked for ever."""
    from rtp.capture.paths import PathProfile

    sc, blockers = scene
    good = dict(name="mine", speed=2.0, turn_rate=90.0, wander=10.0, sway=5.0, sway_period=3.0)
    path = camera_path(sc, 30, PathProfile(**good), seed=0, blockers=blockers)  # type: ignore[arg-type]
    assert path.profile == "mine" and len(path) == 30
    for field, value, words in (("speed", 0.0, r"speed \(m/s\): expected a finite number > 0 and <= 100, got 0.0"),
                                ("speed", -1.0, "speed"), ("speed", float("inf"), "speed"), ("speed", "2", "speed"),
                                ("turn_rate", -45.0, r"turn_rate \(degrees/s\): expected a finite number >= 0"),
                                ("turn_rate", float("nan"), "turn_rate"), ("wander", -1.0, "wander"),
                                ("sway", 500.0, r"sway \(degrees\): expected a finite number >= 0 and <= 180"),
                                ("sway_period", 0.0, r"sway_period \(s\): expected a finite number > 0, got 0.0"),
                                ("name", 3, "path profile name: expected a string, got 3")):
        with pytest.raises(ViewpointError, match=words):
            camera_path(sc, 10, PathProfile(**{**good, field: value}), seed=0,  # type: ignore[arg-type]
                        blockers=blockers)


def test_the_docs_give_the_views_peak_turn_rate(scene) -> None:  # noqa: ANN001
    """The view turns after the direction of travel at up to turn_rate and sways on top of it: its yaw turns at
    up to turn_rate + 2 pi sway / sway_period, 55 and 338 degrees/s, as measured; the docs said 45 and 240."""
    from pathlib import Path

    sc, blockers = scene
    docs = (Path(__file__).resolve().parents[1] / "docs" / "evaluation.md").read_text()
    said = []
    for name in ("slow", "fast"):
        prof = PATH_PROFILES[name]
        peak = prof.turn_rate + 2 * math.pi * prof.sway / prof.sway_period
        yaw = np.array([c.yaw for c in camera_path(sc, 300, name, seed=0, blockers=blockers).cameras])
        measured = np.abs((np.diff(yaw) + 180) % 360 - 180).max() * 60
        assert 0.97 * peak <= measured <= peak + 1e-6, name
        said.append(f"{peak:.0f}")
    assert f"the view's yaw turns at up to {said[0]} and {said[1]}\ndegrees/s" in docs


def test_unseen_shares_names_a_bad_path_or_size(scene) -> None:  # noqa: ANN001
    """Before any renderer: a path that is no CameraPath was an AttributeError, a size of one number a TypeError."""
    sc, blockers = scene
    with pytest.raises(ViewpointError, match="path: expected a CameraPath .*, got str"):
        unseen_shares("path", sc, (64, 48))  # type: ignore[arg-type]
    with pytest.raises(ViewpointError, match=r"size: expected \(width, height\) in pixels, got \(64,\)"):
        unseen_shares(camera_path(sc, 2, blockers=blockers), sc, (64,))  # type: ignore[arg-type]


def test_the_view_turns_the_short_way_to_the_direction_of_travel() -> None:
    """The view turns after the direction of the path 1 m ahead, the short way round. It followed that
    direction unwrapped: where the path looped or turned back faster than the view could turn (the fast path
    of procedural:0, seed 0, 300 frames), the view lagged more than a half turn and then turned the long way,
    a whole extra turn on past the direction of travel (frames 108-258 facing away from it). Now it turns at
    the turn rate towards that direction, never away from it."""
    from rtp.capture.paths import PathProfile

    sc, blockers = load_scene("procedural:0", None, None, None)
    fast = PATH_PROFILES["fast"]
    still = PathProfile("fast", fast.speed, fast.turn_rate, fast.wander, sway=0.0, sway_period=fast.sway_period)
    path = camera_path(sc, 300, still, seed=0, blockers=blockers)  # (the fast path without its sway)
    pos = np.array([c.position for c in path.cameras])[:, [0, 2]]
    yaw = np.array([c.yaw for c in path.cameras])
    ahead = round(path.fps / fast.speed)  # the camera 1 m further along the path
    look = pos[ahead:] - pos[:-ahead]
    aim = np.degrees(np.arctan2(-look[:, 0], -look[:, 1]))
    off = (aim[1:] - yaw[:len(aim) - 1] + 180) % 360 - 180  # where the view should turn, from the frame before
    turn = (np.diff(yaw)[:len(off)] + 180) % 360 - 180  # where it turned
    clear = (np.abs(off) > 20) & (np.abs(off) < 160)  # (not the direction's own noise, nor a reversal)
    assert clear.sum() > 10 and np.all(np.sign(turn[clear]) == np.sign(off[clear]))
    assert np.all(np.abs(turn) <= fast.turn_rate / path.fps + 1e-6)
