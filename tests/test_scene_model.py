"""The scene model refuses what the renderer would draw wrongly: each bad field is a ParameterError
naming the class and field when the object is made (a NaN camera gave NaN matrices and a black
frame; a mesh with an index past its vertices, a GL error or garbage later)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.scene import (
    Camera,
    Material,
    Mesh,
    PointLight,
    Scene,
    SpawnPoint,
    SunLight,
    box_mesh,
    checker_texture,
    quad_mesh,
    sphere_mesh,
)


def _mesh(**changes: Any) -> Mesh:
    fields = {"positions": np.zeros((3, 3), np.float32), "normals": np.tile([0, 1, 0], (3, 1)).astype(np.float32),
              "uvs": np.zeros((3, 2), np.float32), "indices": np.array([[0, 1, 2]], np.uint32), "material": 0}
    return Mesh(**{**fields, **changes})


BAD: list[tuple[str, Any, str]] = [
    ("camera nan position", lambda: Camera((math.nan, 0.0, 0.0)), "Camera.position"),
    ("camera 2d position", lambda: Camera((0.0, 0.0)), "Camera.position"),  # type: ignore[arg-type]
    ("camera inf yaw", lambda: Camera((0.0, 0.0, 0.0), yaw=math.inf), "Camera.yaw"),
    ("camera fov 0", lambda: Camera((0.0, 0.0, 0.0), fov_y=0.0), "Camera.fov_y"),
    ("camera fov 180", lambda: Camera((0.0, 0.0, 0.0), fov_y=180.0), "Camera.fov_y"),
    # a denormal field of view: tan() of it is 0 (a ZeroDivisionError in projection(); rooms fuzz suite at
    # RTP_FUZZ_SCALE=10, 2026-12-03), or its inverse infinite
    ("camera fov 5e-324", lambda: Camera((0.0, 0.0, 0.0), fov_y=5e-324), "Camera.fov_y: .*projection is finite"),
    ("camera fov 1e-308", lambda: Camera((0.0, 0.0, 0.0), fov_y=1e-308), "Camera.fov_y: .*projection is finite"),
    ("camera aspect 5e-324", lambda: Camera((0.0, 0.0, 0.0)).projection(5e-324), "Camera.projection.aspect"),
    ("camera near 0", lambda: Camera((0.0, 0.0, 0.0), near=0.0), "Camera.near"),
    ("camera far before near", lambda: Camera((0.0, 0.0, 0.0), near=1.0, far=0.5), "Camera.far"),
    # clip planes whose projection overflows: 2 far near was infinite, a -inf projection matrix
    ("camera far 1.7e308", lambda: Camera((0.0, 0.0, 0.0), near=1.0, far=1.7e308), "Camera.far: .*projection is finite"),
    ("camera near and far 1e308", lambda: Camera((0.0, 0.0, 0.0), near=1e308, far=1.5e308), "Camera.far"),
    ("camera string pitch", lambda: Camera((0.0, 0.0, 0.0), pitch="5"), "Camera.pitch"),  # type: ignore[arg-type]
    ("mesh nan positions", lambda: _mesh(positions=np.full((3, 3), np.nan, np.float32)), "Mesh.positions"),
    # float64 past float32's range: taken, then drawn as infinities by every renderer (they upload float32)
    ("mesh float64 positions past float32", lambda: _mesh(positions=np.full((3, 3), 1e39)), "Mesh.positions: .*float32"),
    ("mesh float64 uvs past float32", lambda: _mesh(uvs=np.full((3, 2), -1e300)), "Mesh.uvs: .*float32"),
    ("mesh flat positions", lambda: _mesh(positions=np.zeros(9, np.float32)), "Mesh.positions"),
    ("mesh normals short", lambda: _mesh(normals=np.zeros((2, 3), np.float32)), "Mesh.normals"),
    ("mesh uvs 3 columns", lambda: _mesh(uvs=np.zeros((3, 3), np.float32)), "Mesh.uvs"),
    ("mesh float indices", lambda: _mesh(indices=np.array([[0.0, 1.0, 2.0]])), "Mesh.indices"),
    ("mesh index past vertices", lambda: _mesh(indices=np.array([[0, 1, 3]], np.uint32)), "Mesh.indices"),
    ("mesh negative index", lambda: _mesh(indices=np.array([[0, 1, -1]], np.int64)), "Mesh.indices"),
    ("mesh material -1", lambda: _mesh(material=-1), "Mesh.material"),
    ("material colour 3", lambda: Material("m", base_color=(1.0, 1.0, 1.0)), "Material.base_color"),  # type: ignore[arg-type]
    ("material colour 255", lambda: Material("m", base_color=(255, 0, 0, 255)), "Material.base_color"),
    ("material roughness nan", lambda: Material("m", roughness=math.nan), "Material.roughness"),
    ("material emissive < 0", lambda: Material("m", emissive=(-1.0, 0.0, 0.0)), "Material.emissive"),
    ("material cutoff 2", lambda: Material("m", alpha_cutoff=2.0), "Material.alpha_cutoff"),
    ("material rgb texture", lambda: Material("m", texture=np.zeros((4, 4, 3), np.uint8)), "Material.texture"),
    ("material float texture", lambda: Material("m", texture=np.zeros((4, 4, 4), np.float32)), "Material.texture"),
    ("sun zero direction", lambda: SunLight(direction=(0.0, 0.0, 0.0)), "SunLight.direction"),
    # a length but no direction (denormal), or an infinite length: NaN light poses, a LinAlgError in to_pyrender_scene
    ("sun denormal direction", lambda: SunLight(direction=(1e-320, 0.0, 0.0)), "SunLight.direction"),
    ("sun direction of 1e-30", lambda: SunLight(direction=(0.0, -1e-30, 0.0)), "SunLight.direction: .*>= 1e-06"),
    ("sun direction of infinite length", lambda: SunLight(direction=(1e308, 1e308, 0.0)), "SunLight.direction"),
    ("sun negative intensity", lambda: SunLight(intensity=-1.0), "SunLight.intensity"),
    ("point light radius 0", lambda: PointLight((0.0, 0.0, 0.0), radius=0.0), "PointLight.radius"),
    ("spawn nan", lambda: SpawnPoint((0.0, math.nan, 0.0)), "SpawnPoint.position"),
    ("scene material past the list", lambda: Scene("s", [_mesh(material=1)], [Material("m")]), r"meshes\[0\].material"),
    ("scene a tuple of meshes", lambda: Scene("s", (_mesh(),), [Material("m")]), "Scene.meshes"),  # type: ignore[arg-type]
    ("scene a dict as material", lambda: Scene("s", [], [{"name": "m"}]), "Scene.materials"),  # type: ignore[list-item]
    ("scene ambient -1", lambda: Scene("s", [], [], ambient=-1.0), "Scene.ambient"),
    ("scene sun None", lambda: Scene("s", [], [], sun=None), "Scene.sun"),  # type: ignore[arg-type]
    # the builders: numpy's ValueError or OverflowError, an inside-out box or sphere, a sphere of no triangles
    ("box of two numbers", lambda: box_mesh((0, 0), (1, 1)), "box_mesh.lo: expected 3 finite numbers"),
    ("box inside out", lambda: box_mesh((1, 1, 1), (0, 0, 0)), "box_mesh: expected hi above lo on every axis"),
    ("sphere radius -1", lambda: sphere_mesh((0, 0, 0), -1), "sphere_mesh.radius"),
    ("sphere of 0 segments", lambda: sphere_mesh((0, 0, 0), 1, segments=0), "sphere_mesh.segments"),
    ("quad of parallel axes", lambda: quad_mesh((0, 0, 0), (1, 0, 0), (2, 0, 0)), "span a plane"),
    # uv_scale was not checked: numpy's ValueError, or an error naming Mesh.uvs
    ("quad uv_scale a string", lambda: quad_mesh((0, 0, 0), (1, 0, 0), (0, 1, 0), uv_scale="ab"), "quad_mesh.uv_scale"),
    ("quad uv_scale of 3", lambda: quad_mesh((0, 0, 0), (1, 0, 0), (0, 1, 0), uv_scale=(1, 2, 3)), "quad_mesh.uv_scale"),
    ("quad uv_scale nan", lambda: quad_mesh((0, 0, 0), (1, 0, 0), (0, 1, 0), uv_scale=(math.nan, 1)), "quad_mesh.uv_scale"),
    ("checker size -1", lambda: checker_texture(-1), "checker_texture.size"),
    # more cells than pixels: 8 cells over 4 pixels was one plain colour, no checkerboard
    ("checker 8 cells of 4 pixels", lambda: checker_texture(4, 8), r"checker_texture.cells: expected at most size \(4\)"),
    ("checker colour 300", lambda: checker_texture(8, 2, a=(300, 0, 0)), r"checker_texture.a: .* \[0, 255\]"),
    # a colour in [0, 1] read as bytes: 0.5 was drawn as 0; "no" was taken for True
    ("checker colour 0.5", lambda: checker_texture(8, 2, b=(0.5, 0.5, 0.5)), r"checker_texture.b: expected integers"),
    ("checker alpha_holes 'no'", lambda: checker_texture(8, 2, alpha_holes="no"),  # type: ignore[arg-type]
     "checker_texture.alpha_holes: expected True or False"),
]


@pytest.mark.parametrize("make, words", [(m, w) for _, m, w in BAD], ids=[n for n, _, _ in BAD])
def test_bad_fields_are_parameter_errors(make: Any, words: str) -> None:
    with pytest.raises(sdk.ParameterError, match=words):
        make()


def test_good_scenes_are_taken_as_given() -> None:
    mesh = box_mesh((0, 0, 0), (1, 1, 1), 0)
    scene = Scene("ok", [mesh], [Material("m", texture=np.zeros((2, 2, 4), np.uint8), alpha_cutoff=0.5)],
                  point_lights=[PointLight((0.0, 1.0, 0.0))], spawn_points=[SpawnPoint((0.0, 1.6, 0.0), yaw=np.float64(30))])
    assert scene.meshes[0] is mesh and mesh.positions.dtype == np.float32
    cam = Camera((np.float32(1.0), 2, 3.0), yaw=np.float64(10.0), pitch=-95.0)  # numpy numbers; pitch past 90 wraps
    assert np.isfinite(cam.view_projection(64, 32)).all()


def test_mesh_floats_are_stored_as_float32() -> None:
    """The fields are documented float32: float64 and float16 ones are converted (and checked as float32)."""
    m = _mesh(positions=np.ones((3, 3)), normals=np.tile([0, 1, 0], (3, 1)).astype(np.float16), uvs=np.zeros((3, 2)))
    assert m.positions.dtype == m.normals.dtype == m.uvs.dtype == np.float32
    assert SunLight(direction=(0.0, -1e-6, 0.0)).direction == (0.0, -1e-6, 0.0)  # a length from 1e-6 up


def test_bounds_skip_meshes_without_vertices() -> None:
    """An empty mesh is a valid one (a source's level part with nothing left); bounds were numpy's ValueError."""
    empty = _mesh(positions=np.zeros((0, 3), np.float32), normals=np.zeros((0, 3), np.float32),
                  uvs=np.zeros((0, 2), np.float32), indices=np.zeros((0, 3), np.uint32))
    lo, hi = Scene("s", [empty, box_mesh((0, 1, 2), (1, 2, 3))], [Material("m")]).bounds
    assert lo.tolist() == [0, 1, 2] and hi.tolist() == [1, 2, 3]
    lo, hi = Scene("s", [empty], [Material("m")]).bounds
    assert lo.tolist() == hi.tolist() == [0, 0, 0]


@pytest.mark.parametrize("pitch", [-90.0, 90.0])
def test_a_camera_looking_straight_down_or_up_keeps_its_yaw(pitch: float) -> None:
    """At pitch +-90 the view direction is parallel to world up: the right axis fell back to world +X, so the
    yaw was lost (a top-down camera drew the same image at every yaw) and the view jumped next to the pole."""
    for yaw in (0.0, 90.0, -135.0):
        at, near = Camera((0.0, 0.0, 0.0), yaw=yaw, pitch=pitch), Camera((0.0, 0.0, 0.0), yaw=yaw, pitch=pitch * (1 - 1e-8))
        np.testing.assert_allclose(at.rotation(), near.rotation(), atol=1e-5)
        r = at.rotation()
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        np.testing.assert_allclose(r[:, 0], [math.cos(math.radians(yaw)), 0.0, -math.sin(math.radians(yaw))], atol=1e-12)


def test_cameras_are_frozen_values_of_floats() -> None:
    """A numpy or list position made a 'frozen' camera that == raised on (ValueError), hash() refused and an
    in-place edit moved; numpy scalars stayed numpy ones (json.dumps of a capture's camera fields failed)."""
    import json

    a = Camera(np.array([0.0, 1.0, 2.0]), yaw=np.float32(10.0), pitch=np.int64(-5), fov_y=np.float64(60.0))
    b = Camera([0, 1, 2], yaw=10, pitch=-5, fov_y=60)
    assert a == b and hash(a) == hash(b) and a.position == (0.0, 1.0, 2.0)
    assert all(type(v) is float for v in (*a.position, a.yaw, a.pitch, a.fov_y, a.near, a.far))
    json.dumps({"yaw": a.yaw, "pitch": a.pitch, "position": a.position})


def test_a_checker_of_one_pixel_cells_alternates_every_pixel() -> None:
    img = checker_texture(4, 4, a=(200, 200, 200), b=(10, 10, 10))
    assert img[..., 0].tolist() == [[200, 10, 200, 10], [10, 200, 10, 200]] * 2


def test_the_camera_keeps_the_documented_conventions() -> None:
    """rtp.scene and docs/architecture.md: world right-handed, Y up; view space looks down -Z; yaw 0 looks down
    world -Z, positive yaw turns left (counter-clockwise seen from above), positive pitch looks up; an OpenGL
    projection (near plane to NDC z -1, far to +1); and the coverage rays of the viewpoint sampler (rows from the
    top, columns from the left) land where the renderer's matrices put them."""
    from rtp.capture.viewpoints import ray_grid

    def in_view(cam: Camera, p: Any) -> np.ndarray:
        return (cam.view() @ np.array([*p, 1.0]))[:3]

    c = Camera((1.0, 2.0, 3.0))
    np.testing.assert_allclose(c.forward, [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(in_view(c, (1, 2, -2)), [0, 0, -5], atol=1e-12)  # ahead: -Z
    np.testing.assert_allclose(in_view(c, (2, 2, 3)), [1, 0, 0], atol=1e-12)  # world +X on the right
    np.testing.assert_allclose(in_view(c, (1, 3, 3)), [0, 1, 0], atol=1e-12)  # world up is up
    np.testing.assert_allclose(Camera((0, 0, 0), yaw=90.0).forward, [-1, 0, 0], atol=1e-12)  # left of -Z: -X
    assert Camera((0, 0, 0), pitch=30.0).forward[1] > 0
    for cam in (c, Camera((0, 0, 0), yaw=90.0), Camera((0, 0, 0), pitch=30.0), Camera((4, -1, 2), yaw=-140.0, pitch=-35.0)):
        r = cam.rotation()
        np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
        assert np.linalg.det(r) == pytest.approx(1.0)  # right-handed
        np.testing.assert_allclose(in_view(cam, np.add(cam.position, cam.forward)), [0, 0, -1], atol=1e-12)
    m = c.projection(16 / 9)
    for z, ndc in ((-c.near, -1.0), (-c.far, 1.0)):
        clip = m @ np.array([0.0, 0.0, z, 1.0])
        assert clip[2] / clip[3] == pytest.approx(ndc)
    vp = c.view_projection(16, 9)
    for ray, corner in zip(ray_grid(c, 16 / 9, 2, 2), [(-0.5, 0.5), (0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)]):
        clip = vp @ np.array([*np.add(c.position, ray), 1.0])
        np.testing.assert_allclose(clip[:2] / clip[3], corner, atol=1e-12)
