"""Viewpoint sampling on procedural scenes: validity rules, motion profiles, determinism."""

from __future__ import annotations

import numpy as np
import pytest

from rtp.capture.scenes import procedural
from rtp.capture.scenes._geometry import MeshBuilder
from rtp.capture.viewpoints import (
    MOTION_PROFILES,
    SOLID,
    MotionProfile,
    ViewpointError,
    VoxelGrid,
    free_space,
    point_triangle_distance,
    ray_grid,
    sample_viewpoints,
    scene_triangles,
    segment_hits_triangles,
)
from rtp.scene import Material, Scene, SpawnPoint


@pytest.fixture(scope="module")
def scene() -> Scene:
    return procedural(0)


@pytest.fixture(scope="module")
def views(scene):
    return {p: sample_viewpoints(scene, 12, seed=5, profile=p) for p in ("slow", "fast", "frame")}


def test_point_triangle_distance_matches_sampling():
    rng = np.random.default_rng(0)
    tris = rng.normal(size=(20, 3, 3))
    p = rng.normal(size=3)
    d = point_triangle_distance(p, tris)
    # brute force: dense barycentric samples
    w = rng.dirichlet([1, 1, 1], size=20000)
    for t, dt in zip(tris, d):
        brute = np.linalg.norm(w @ t - p, axis=1).min()
        assert dt <= brute + 1e-9 and brute - dt < 0.05


def test_segment_triangle():
    tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    assert segment_hits_triangles(np.array([0.2, 0.2, -1.0]), np.array([0.2, 0.2, 1.0]), tri)[0]
    assert not segment_hits_triangles(np.array([0.2, 0.2, 0.5]), np.array([0.2, 0.2, 1.0]), tri)[0]
    assert not segment_hits_triangles(np.array([0.9, 0.9, -1.0]), np.array([0.9, 0.9, 1.0]), tri)[0]


def test_flood_fill_stays_inside_a_closed_room():
    b = MeshBuilder()
    # a closed 4 x 3 x 4 m room of thin walls (inward-facing quads only), and the outside is bounded by a
    # larger box far away so there is free space outside that must not be reached
    b.box(0, (-2, 0, -2), (2, 3, 2))
    b.box(0, (-6, -1, -6), (6, 5, 6))
    s = Scene("room", b.meshes(), [Material("m")], spawn_points=[SpawnPoint((0.0, 1.5, 0.0))])
    g = VoxelGrid(scene_triangles(s), 0.25)
    reach = g.flood(np.array([[0.0, 1.5, 0.0]]), g.occ == 0)
    c = g.centre(np.flatnonzero(reach))
    assert len(c) > 0
    assert (np.abs(c[:, 0]) < 2).all() and (np.abs(c[:, 2]) < 2).all() and (c[:, 1] > 0).all() and (c[:, 1] < 3).all()


def test_a_spawn_point_outside_the_level_starts_no_flood(caplog):
    """A spawn point far outside the level (in centimetres where the level is in metres, say) was clipped onto
    the voxel grid's side and the flood started there: one 100 m over a closed room flooded the room. Now it
    starts none, with a warning, and a scene whose spawn points all lie outside is a ViewpointError."""
    b = MeshBuilder()
    b.box(0, (-2, 0, -2), (2, 3, 2))

    def room(*spawns):
        return Scene("room", b.meshes(), [Material("m")], spawn_points=[SpawnPoint(p) for p in spawns])

    inside = free_space(room((0.0, 1.5, 0.0)), max_height=None)[2]
    for far in ((0.0, 100.0, 0.0), (50.0, 1.5, 0.0), (0.0, -50.0, 0.0)):
        with pytest.raises(ViewpointError, match=r"none of its 1 spawn points lies within the level .* at \("):
            free_space(room(far), max_height=None)
    with caplog.at_level("WARNING", logger="rtp.capture"):
        both = free_space(room((0.0, 100.0, 0.0), (0.0, 1.5, 0.0)), max_height=None)[2]
    assert np.array_equal(both, inside)
    assert any("1 of its 2 spawn points lie outside the level" in r.getMessage() for r in caplog.records)
    # (one on the bounds, a wall's voxel, still finds the free voxel beside it, as before)
    assert np.array_equal(free_space(room((2.0, 1.5, 0.0)), max_height=None)[2], inside)


def test_viewpoints_are_valid(scene, views):
    tris = scene_triangles(scene)
    lo, hi = scene.bounds
    grid = VoxelGrid(tris, 0.25)
    for name, pairs in views.items():
        prof = MOTION_PROFILES[name]
        assert len(pairs) == 12
        for prev, cam in pairs:
            for c in (prev, cam):
                p = np.asarray(c.position)
                assert (p > lo).all() and (p < hi).all()  # inside the level
                assert point_triangle_distance(p, tris).min() >= 0.3 - 1e-9  # no intersection
                assert abs(c.pitch) <= 20.0 and -180.0 <= c.yaw <= 180.0
                hits = grid.march(p, ray_grid(c, 16 / 9, 32, 18), 100.0)
                assert (hits == SOLID).mean() >= 0.85  # coverage rule
                assert 0.0 < p[1] < 4.5  # between floor and ceiling: inside the rooms, not above the roof
            a, b = np.asarray(prev.position), np.asarray(cam.position)
            assert np.linalg.norm(a - b) <= prof.max_translation + 1e-9
            assert not segment_hits_triangles(a, b, tris).any()  # unobstructed motion
            dyaw = (prev.yaw - cam.yaw + 180) % 360 - 180
            assert abs(dyaw) <= prof.max_rotation + 1e-9 and abs(prev.pitch - cam.pitch) <= prof.max_rotation + 1e-9


def test_profiles_differ_in_motion(views):
    def mean_motion(pairs):
        return np.mean([np.linalg.norm(np.subtract(p.position, c.position)) for p, c in pairs])

    assert mean_motion(views["fast"]) > 2 * mean_motion(views["slow"])
    assert mean_motion(views["slow"]) > 2 * mean_motion(views["frame"])  # one 60 Hz frame of the fast path


def test_viewpoints_deterministic(scene, views):
    again = sample_viewpoints(scene, 12, seed=5, profile="slow")
    assert again == views["slow"]
    other = sample_viewpoints(scene, 12, seed=6, profile="slow")
    assert other != views["slow"]
    custom = sample_viewpoints(scene, 2, seed=5, profile=MotionProfile("still", 0.0, 0.0))
    assert all(p == c for p, c in custom)


def test_viewpoint_errors(scene):
    with pytest.raises(ViewpointError, match="profile"):
        sample_viewpoints(scene, 1, 0, profile="medium")
    bare = Scene("bare", scene.meshes, scene.materials, spawn_points=[])
    with pytest.raises(ViewpointError, match="spawn"):
        sample_viewpoints(bare, 1, 0)
    with pytest.raises(ViewpointError, match="valid viewpoints"):
        sample_viewpoints(scene, 5, 0, clearance=50.0, max_attempts=20)
    for kwargs, words in (({"seed": -1}, "seed: expected an integer >= 0"), ({"n": 2.5}, "n: expected an integer"),
                          ({"clearance": float("nan")}, "clearance"), ({"min_coverage": -0.1}, "min_coverage"),
                          ({"min_coverage": []}, "min_coverage"), ({"rays": (0, 3)}, "rays"), ({"fov_y": 0}, "fov_y"),
                          # (an increasing sequence was taken, though each level is a lower fallback)
                          ({"min_coverage": (0.2, 0.5)}, r"min_coverage: expected a number or a decreasing sequence"),
                          ({"min_coverage": (0.5, 0.5)}, r"min_coverage: expected a number or a decreasing sequence"),
                          ({"pitch_limit": 91}, "pitch_limit"), ({"max_attempts": -1}, "max_attempts"),
                          ({"aspect": -1}, "aspect"), ({"voxel": float("inf")}, "voxel"),
                          # (rays overflowing to nan were an IndexError of the faster march: RTP_FUZZ_SCALE=20)
                          ({"aspect": 1e308}, "aspect: expected a finite number > 0 and <= 1e\\+06")):
        with pytest.raises(ViewpointError, match=words):  # (seed -1 and nan were numpy's ValueErrors)
            sample_viewpoints(scene, **{"n": 1, "seed": 0, **kwargs})  # type: ignore[arg-type]


def test_a_clearance_past_the_level_is_refused_in_seconds(scene):
    """clearance=1e6 dilated the solid voxels 4 million times (minutes) before refusing every draw: now
    past MAX_METRES it is refused at once, and within it a dilation stops at the grid's side."""
    with pytest.raises(ViewpointError, match="clearance: expected a finite number >= 0 and <= 1000"):
        sample_viewpoints(scene, 1, 0, clearance=1e6)
    with pytest.raises(ViewpointError, match="valid viewpoints"):
        sample_viewpoints(scene, 1, 0, clearance=900.0, max_attempts=50)
    _, _, reach, cand = free_space(scene, clearance=900.0)
    assert reach.any() and not cand.any()


def test_viewpoints_are_a_stream_through_the_coverage_fallback(scene):
    """Extending a dataset (larger n) keeps the pairs already captured, fallback included."""
    five = sample_viewpoints(scene, 5, seed=9, profile="fast")
    assert sample_viewpoints(scene, 2, seed=9, profile="fast") == five[:2]
    stats: dict = {}
    lax = sample_viewpoints(scene, 3, seed=9, profile="fast", min_coverage=(1.01, 0.5), max_attempts=30, stats=stats)
    assert stats["coverage"] == 0.5 and len(lax) == 3
    assert sample_viewpoints(scene, 2, seed=9, profile="fast", min_coverage=(1.01, 0.5), max_attempts=30) == lax[:2]
    with pytest.raises(ViewpointError, match="coverage down to 0.50"):
        sample_viewpoints(scene, 2, seed=9, min_coverage=(1.01, 0.5), max_attempts=0)


def test_eye_placement_stands_on_the_floors_at_the_spawn_eye_height(scene):
    """placement='eye': both cameras of a pair stand at the spawn points' eye height over their own
    floor (the procedural rooms spawn at 1.6 m), the previous one moved along the floors (no
    vertical motion on a flat floor; its floor at most 1.2 m below or 0.6 m above the current
    one's), every 'free' rule kept."""
    from rtp.capture.viewpoints import _Floors, _spawn_eye_height, free_space

    tris = scene_triangles(scene)
    _, grid, _, _ = free_space(scene)
    floors = _Floors(grid)
    eye = _spawn_eye_height(scene, floors)
    assert eye == pytest.approx(1.6, abs=grid.voxel / 2)
    stats: dict = {}
    pairs = sample_viewpoints(scene, 10, seed=5, profile="fast", placement="eye", stats=stats)
    assert stats["placement"] == "eye" and stats["eye_height"] == eye and "floor" in stats["rejected"]
    prof = MOTION_PROFILES["fast"]
    for prev, cam in pairs:
        heights = []
        for c in (prev, cam):
            p = np.asarray(c.position)
            heights.append(p[1] - floors.below(p))
            assert point_triangle_distance(p, tris).min() >= 0.3 - 1e-9
            assert abs(c.pitch) <= 20.0
        assert heights == pytest.approx([eye, eye], abs=1e-9)
        a, b = np.asarray(prev.position), np.asarray(cam.position)
        assert np.hypot(*(a - b)[[0, 2]]) <= prof.max_translation + 1e-9
        assert -1.2 - 1e-9 <= a[1] - b[1] <= 0.6 + 1e-9
        assert not segment_hits_triangles(a, b, tris).any()
    free = sample_viewpoints(scene, 10, seed=5, profile="fast")
    free_over = [c.position[1] - floors.below(np.asarray(c.position)) for _, c in free]
    assert np.std(free_over) > 0.1  # the default still floats the cameras: the two differ
    assert sample_viewpoints(scene, 4, seed=5, profile="fast", placement="eye") == pairs[:4]  # a stream too
    with pytest.raises(ViewpointError, match="unknown placement 'crouch'"):
        sample_viewpoints(scene, 1, 0, placement="crouch")


def test_the_viewpoint_stream_is_the_one_datasets_were_captured_with():
    """A dataset resumes or grows only while capture plans the cameras it planned before (its samples
    are compared with the plan and recaptured when they differ). These pairs were planned before the
    coverage march was made faster (2026-12-04); a change here recaptures every dataset. (Should numpy
    change its generator's stream, this fails too: that is the same news.)"""
    def pairs(placement, profile):
        got = sample_viewpoints(procedural(0), 2, 7, profile, placement=placement, min_coverage=(0.85, 0.6))
        return [[[*c.position, c.yaw, c.pitch] for c in pair] for pair in got]

    assert pairs("free", "slow") == [
        [[5.066531207119099, 2.9987628461204103, -3.3703790086353442, -73.71284559058502, 12.947968324757433],
         [5.055094923631065, 2.743921419581066, -3.2767861236449303, -71.94013743195885, 14.942137815850472]],
        [[1.3535271665883741, 2.4910053858075565, 5.427564804815528, 16.200955051537903, 20.0],
         [1.394508870302203, 2.6612690734904296, 5.54304914359691, 19.25904674681729, 19.820011337375703]]]
    assert pairs("eye", "fast") == [
        [[5.56427723253923, 1.6, 2.3725467257873984, -77.84916462737944, 8.294906178873672],
         [5.305094923631065, 1.6, 3.2232138763550697, -71.94013743195885, 14.942137815850472]],
        [[1.6660952647432383, 1.6, -2.9457499907625833, 33.92785117727385, 11.279272284443671],
         [1.394508870302203, 1.6, -1.9569508564030897, 19.25904674681729, 19.820011337375703]]]


def test_the_coverage_march_meets_what_a_plain_march_meets(scene):
    """VoxelGrid.march reads a point outside the grid from the grid's border (all OUTSIDE) instead of
    testing it, and steps in growing chunks: it must meet, ray for ray, what a march that tests every
    point meets, from inside the level and from outside its bounds."""
    from rtp.capture.viewpoints import FREE, OUTSIDE

    grid = VoxelGrid(scene_triangles(scene), 0.25)

    def plain(origin, dirs, max_distance):
        step = grid.voxel * 0.5
        hi = np.array(grid.shape)
        res = np.zeros(len(dirs), np.uint8)
        for r, d in enumerate(dirs):
            for t in np.arange(step, max_distance + step, step):
                i = np.floor((origin + d * t - grid.origin) / grid.voxel).astype(np.int64)
                v = grid.occ[tuple(i)] if ((i >= 0) & (i < hi)).all() else OUTSIDE
                if v != FREE:
                    res[r] = v
                    break
        return res

    rng = np.random.default_rng(3)
    lo, hi = scene.bounds
    origins = [np.asarray(c.position) for pair in sample_viewpoints(scene, 3, 1) for c in pair]
    origins += [np.asarray(hi) + 2.0, np.asarray(lo) - 5.0]  # outside the bounds: the border is met at once
    for origin in origins:
        dirs = rng.normal(size=(40, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        dirs[:2] = [[np.nan, 0.0, 1.0], [np.inf, 0.0, 0.0]]  # (an absurd aspect's overflow: they go nowhere)
        for max_distance in (1.0, 30.0):  # (short: rays that meet nothing stay FREE)
            got = grid.march(origin, dirs, max_distance)
            with np.errstate(invalid="ignore"):
                np.testing.assert_array_equal(got, plain(origin, dirs, max_distance))
    assert (grid.march(origins[0], dirs, 0.5) == FREE).any()


def test_sample_viewpoints_reports_each_pair_as_it_is_found(scene):
    found: list[int] = []
    pairs = sample_viewpoints(scene, 4, 2, progress=found.append)
    assert found == [1, 2, 3, 4] and pairs == sample_viewpoints(scene, 4, 2)
    with pytest.raises(ViewpointError, match="progress: expected None or a function"):
        sample_viewpoints(scene, 1, 0, progress=3)  # type: ignore[arg-type]


def test_profiles_share_only_the_first_current_camera(scene):
    """docs/scenes.md said that slow and fast with one seed share the current cameras and differ only in the
    previous ones; each previous viewpoint takes as many draws as its tries, so the streams part after the first
    pair, as the docs now say."""
    from pathlib import Path

    slow, fast = (sample_viewpoints(scene, 6, seed=5, profile=p) for p in ("slow", "fast"))
    assert slow[0][1] == fast[0][1] and [c for _, c in slow[1:]] != [c for _, c in fast[1:]]
    docs = " ".join((Path(__file__).resolve().parents[1] / "docs" / "scenes.md").read_text().split())
    assert "share the current cameras and differ only in the previous ones" not in docs
    assert "the same seed share the first current camera only" in docs


@pytest.mark.parametrize("height", [0.0, 0.5])
def test_a_flat_level_gets_a_grid_within_the_voxel_budget(height):
    """The coarser voxel was the cube root of the bounds' volume over the budget, which leaves out the grid's
    padding: a flat level (a ground quad, its height 0) kept 0.25 m voxels, a 10 km quad 4.8e9 of them (a
    MemoryError), and a nearly flat one got grids several times the budget. Now the grid itself fits."""
    tris = np.array([[[0, 0, 0], [200, height, 0], [0, 0, 200]], [[200, height, 0], [200, height, 200], [0, 0, 200]]],
                    np.float64)
    grid = VoxelGrid(tris, 0.25, max_voxels=20_000)
    assert np.prod(grid.shape) <= 20_000 and grid.voxel > 0.25
    assert (grid.occ == SOLID).any()
    # a level the first guess fits keeps it (every map of the scene cache does: the datasets' grids)
    box = np.array([[[0, 0, 0], [200, 100, 0], [0, 100, 200]]], np.float64)
    assert VoxelGrid(box, 0.25, max_voxels=2_000_000).voxel == pytest.approx((4e6 / 2e6) ** (1 / 3) * 1.05)


def test_a_level_narrower_than_the_clearance_says_so():
    """A room narrower than twice the clearance fails every draw's clearance test, and the error advised a lower
    min_coverage or more draws, which change nothing: it now names the clearance."""
    b = MeshBuilder()
    b.box(0, (0, 0, 0), (0.5, 0.5, 0.5))
    tiny = Scene("tiny", b.meshes(), [Material("m")], spawn_points=[SpawnPoint((0.25, 0.25, 0.25))])
    with pytest.raises(ViewpointError, match=r"'clearance': 40, .* is 0.3 m from every triangle .*: lower clearance"):
        sample_viewpoints(tiny, 1, 0, max_attempts=40)
    assert len(sample_viewpoints(tiny, 1, 0, clearance=0.1, min_coverage=0.5)) == 1


def test_a_seed_gives_the_same_viewpoints_in_any_process():
    """No set or dict order (hash randomisation) reaches the cameras: two interpreters with different hash seeds
    plan the same pairs, in both placements."""
    import os
    import subprocess
    import sys

    code = ("from rtp.capture.scenes import procedural; from rtp.capture.viewpoints import sample_viewpoints; "
            "s = procedural(1); print(repr([sample_viewpoints(s, 2, 3, 'fast', placement=p) for p in ('free', 'eye')]))")
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={**os.environ, "PYTHONHASHSEED": h}).stdout for h in ("0", "1")]
    assert runs[0] == runs[1] and "Camera(" in runs[0]


def test_spawn_search_regions_are_the_connected_components():
    """The spawn search of a mesh file splits its free space into 6-connected regions with numpy alone (scipy
    is no runtime dependency): the same partition as scipy's labelling, on a random grid (many small regions)
    and on a one-voxel serpentine (one region, the longest path a label has to travel)."""
    ndimage = pytest.importorskip("scipy.ndimage")
    from rtp.capture.viewpoints import _regions

    grid = np.random.default_rng(3).random((30, 20, 40)) < 0.45
    snake = np.zeros((42, 3, 42), bool)
    for i in range(1, 41, 2):
        snake[i, 1, 1:41] = True
        if i + 2 < 41:
            snake[i + 1, 1, 40 if i % 4 == 1 else 1] = True
    for passable in (grid, snake):
        passable[[0, -1]] = passable[:, [0, -1]] = passable[:, :, [0, -1]] = False  # (the grid's OUTSIDE border)
        lab = _regions(passable)
        assert (lab[~passable.ravel()] == -1).all()
        ours = lab[passable.ravel()]
        theirs, k = ndimage.label(passable)
        pairs = set(zip(ours.tolist(), theirs.ravel()[passable.ravel()].tolist()))
        assert len(np.unique(ours)) == k == len(pairs)  # (one label of ours for each of theirs, and back)
        assert (ours <= np.flatnonzero(passable.ravel())).all()  # (each the smallest flat index of its region)
    assert len(np.unique(_regions(snake)[snake.ravel()])) == 1
