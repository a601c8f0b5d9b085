"""Scene sources: procedural generator, Quake-3 BSP importer (on a BSP the test writes), glTF/OBJ
through trimesh, pk3 archives and shader scripts, the split list, the scene index, fetching (apt-get and
dpkg-deb replaced by a local fake) and the converted-scene cache. No network."""

from __future__ import annotations

import gzip
import io
import json
import logging
import math
import re
import shutil
import struct
import sys
import time
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import PIL.Image as PIL
import pytest

from rtp import sdk
from rtp.capture import scenes
from rtp.capture.scenes import (
    SceneFormatError,
    SceneNotFoundError,
    UnlistedMapError,
    convert_bsp,
    load_bsp,
    load_splits,
    procedural,
    scene_by_name,
)
from rtp.capture.scenes._bsp import FACE_DT, TEXTURE_DT, UNIT, VERTEX_DT, q3_angle_to_yaw
from rtp.capture.scenes._cache import CACHE_VERSION, load_scene_npz, save_scene_npz
from rtp.capture.scenes._materials import pbr_for_path
from rtp.capture.scenes._pk3 import Pk3Set, parse_shaders
from rtp.sdk import RtpError

from .conftest import damage_zip_member


def _scene_arrays(s):
    out = []
    for m in s.meshes:
        out += [m.positions, m.normals, m.uvs, m.indices, np.array([m.material])]
    for mat in s.materials:
        if mat.texture is not None:
            out.append(mat.texture)
    return out


def _geometric_agreement(scene) -> float:
    agree = total = 0
    for m in scene.meshes:
        p = m.positions[m.indices.astype(np.int64)]
        g = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        n = m.normals[m.indices.astype(np.int64)].sum(1)
        agree += int(((g * n).sum(1) > 0).sum())
        total += len(g)
    return agree / total


# -- procedural -----------------------------------------------------------------------------------

def test_procedural_is_deterministic():
    a, b = procedural(7), procedural(7)
    xa, xb = _scene_arrays(a), _scene_arrays(b)
    assert len(xa) == len(xb)
    for u, v in zip(xa, xb):
        assert u.dtype == v.dtype and np.array_equal(u, v)
    assert a.point_lights == b.point_lights and a.spawn_points == b.spawn_points and a.sun == b.sun
    assert [m.roughness for m in a.materials] == [m.roughness for m in b.materials]
    c = procedural(8)
    assert c.triangle_count != a.triangle_count or not np.array_equal(c.meshes[0].positions, a.meshes[0].positions)
    assert _scene_arrays(procedural(np.int64(7)))[0].tobytes() == xa[0].tobytes()  # a numpy integer is a seed


@pytest.mark.parametrize(("kw", "message"), [
    ({"seed": -5}, r"seed: expected a non-negative integer, got -5"),  # was numpy's "expected non-negative integer"
    ({"seed": 1.5}, r"seed: expected a non-negative integer, got 1.5"),
    ({"seed": True}, r"seed: expected a non-negative integer, got True"),
    ({"seed": 0, "rooms": (0, 2)}, r"rooms: expected \(nx, nz\), integers of at least 1, got \(0, 2\)"),
    ({"seed": 0, "rooms": 2}, r"rooms: expected \(nx, nz\)"),
    # (these were numpy's "high - low < 0" or "low > high", or accepted: a NaN height made NaN walls)
    ({"seed": 0, "room_size": (10.0, 6.0)},
     r"room_size: expected \(low, high\) in metres, numbers with 3.5 <= low <= high <= 1000, got \(10.0, 6.0\)"),
    ({"seed": 0, "room_size": (2.0, 3.0)}, r"room_size: expected .* 3.5 <= low"),
    ({"seed": 0, "room_size": 8.0}, r"room_size: expected \(low, high\)"),
    ({"seed": 0, "height": (math.nan, 4.0)}, r"height: expected \(low, high\) in metres, numbers with 2.5 <= low"),
    ({"seed": 0, "height": (3.0, math.inf)}, r"height: expected"),
    ({"seed": 0, "height": (4.0, 3.0)}, r"height: expected"),
    ({"seed": 0, "objects_per_room": (-1, 3)},
     r"objects_per_room: expected \(low, high\) props a room, integers with 0 <= low <= high <= 100, got \(-1, 3\)"),
    ({"seed": 0, "objects_per_room": (2.5, 3)}, r"objects_per_room: expected"),
    ({"seed": 0, "objects_per_room": (5, 2)}, r"objects_per_room: expected"),
    ({"seed": 0, "texture_size": 100}, r"texture_size: expected a power of two from 16 to 4096, got 100"),
    ({"seed": 0, "texture_size": 8}, r"texture_size: expected a power of two"),
    ({"seed": 0, "name": 3}, r"name: expected a string or None, got 3"),
])
def test_procedural_refuses_bad_arguments_saying_what_it_expected(kw: dict, message: str) -> None:
    with pytest.raises(sdk.ParameterError, match=message) as e:
        procedural(**kw)
    assert e.value.name == list(kw)[-1]


def test_a_procedural_scene_has_one_name():
    """``procedural:1_0`` loaded seed 10, ``procedural:01`` and ``procedural:+1`` seed 1 (Python's int reads
    them): one scene under several names and sample ids. Only plain decimal digits are a seed, in
    load_scene, check_scene and scene_id alike."""
    from rtp.capture import check_scene, load_scene, scene_id

    for name in ("procedural:1_0", "procedural:01", "procedural:+1", "procedural: 1", "procedural:1 ",
                 "procedural:-1", "procedural:\u0661", "procedural:00"):
        for call, args in ((load_scene, (name, None, None, None)), (check_scene, (name, None, None, None)),
                           (scene_id, (name,))):
            with pytest.raises(SceneNotFoundError, match=r"seed is a non-negative integer in decimal digits, without "
                                                         r"a sign, leading zeros, underscores or spaces, e\.g\. "
                                                         r"procedural:0"):
                call(*args)
    assert scene_id("procedural:0") == "procedural_0" and scene_id("procedural:10") == "procedural_10"
    check_scene("procedural:10", None, None, None)
    assert load_scene("procedural:0", None, None, None)[0].name == "procedural-0"


def test_procedural_sanity_and_speed():
    t0 = time.perf_counter()
    s = procedural(0)
    assert time.perf_counter() - t0 < 1.0
    assert s.triangle_count > 1000
    lo, hi = s.bounds
    kinds = set()
    for m in s.meshes:
        assert m.positions.dtype == np.float32 and m.normals.dtype == np.float32 and m.uvs.dtype == np.float32
        assert m.indices.dtype == np.uint32 and m.indices.shape[1] == 3
        assert int(m.indices.max()) < len(m.positions)
        np.testing.assert_allclose(np.linalg.norm(m.normals, axis=1), 1.0, atol=1e-5)
        assert 0 <= m.material < len(s.materials)
        kinds.add(s.materials[m.material].name)
    assert {"floor", "wall", "ceiling", "column", "crate"} <= kinds
    assert _geometric_agreement(s) > 0.999  # CCW front faces
    for mat in s.materials:
        if mat.texture is not None:
            assert mat.texture.dtype == np.uint8 and mat.texture.shape == (256, 256, 4)
        assert 0 <= mat.roughness <= 1 and 0 <= mat.metallic <= 1
    assert len({m.roughness for m in s.materials}) > 5 and any(m.metallic == 1.0 for m in s.materials)
    assert any(m.alpha_cutoff is not None for m in s.materials)
    assert len(s.point_lights) >= 4 and s.sun.direction[1] < 0
    assert len(s.spawn_points) == 4
    for sp in s.spawn_points:
        assert np.all(np.asarray(sp.position) > lo) and np.all(np.asarray(sp.position) < hi)


def test_procedural_textures_tile():
    from rtp.capture.scenes._textures import TEXTURE_KINDS, fbm, make_texture

    for kind in TEXTURE_KINDS:
        t = make_texture(kind, np.random.default_rng(1), 64, (0.8, 0.2, 0.1), (0.1, 0.3, 0.9))
        assert t.shape == (64, 64, 4) and t.dtype == np.uint8
    # the noise that every texture uses wraps seamlessly: the step across the edge is an ordinary step
    n = fbm(np.random.default_rng(3), 128, 4, 5)
    d_in = np.abs(np.diff(n, axis=1)).max()
    assert np.abs(n[:, 0] - n[:, -1]).max() <= 1.5 * d_in
    assert np.abs(n[0, :] - n[-1, :]).max() <= 1.5 * np.abs(np.diff(n, axis=0)).max()
    with pytest.raises(ValueError):
        make_texture("nope", np.random.default_rng(0), 64, (0, 0, 0), (1, 1, 1))


# -- a tiny BSP written by the test ---------------------------------------------------------------

SURF_SKY = 0x4


def _png(rgb, size=8) -> bytes:
    buf = io.BytesIO()
    PIL.new("RGB", (size, size), rgb).save(buf, format="PNG")
    return buf.getvalue()


def _jpg(rgb, size=8) -> bytes:
    buf = io.BytesIO()
    PIL.new("RGB", (size, size), rgb).save(buf, format="JPEG", quality=95)
    return buf.getvalue()


def _quad_z(x0, y0, x1, y1, z, nz=1.0):
    """Four Q3 vertices of an axis-aligned quad at height z (CCW seen from +Z)."""
    return [((x0, y0, z), (0, 0), (0, 0, nz)), ((x1, y0, z), (1, 0), (0, 0, nz)),
            ((x1, y1, z), (1, 1), (0, 0, nz)), ((x0, y1, z), (0, 1), (0, 0, nz))]


def write_test_bsp() -> bytes:
    """A minimal IBSP v46 map: textures, 2 polygon quads, 1 mesh triangle, one 3x3 patch, a sky
    quad, a quad with a missing texture, entities with a spawn point and a light."""
    textures = np.zeros(4, TEXTURE_DT)
    textures["name"] = [b"textures/test/wall", b"textures/test/fancy", b"textures/skies/sky", b"textures/test/missing"]
    textures["flags"] = [0, 0, SURF_SKY, 0]
    textures["contents"] = 1
    verts, meshverts, faces = [], [], []
    cw_quad = [0, 3, 2, 0, 2, 1]  # Q3 front faces are clockwise seen from the front

    def add_face(ftype, tex, vs, mv, size=(0, 0)):
        f = np.zeros(1, FACE_DT)
        f["texture"], f["type"], f["vertex"], f["n_vertexes"] = tex, ftype, len(verts), len(vs)
        f["meshvert"], f["n_meshverts"], f["size"] = len(meshverts), len(mv), size
        verts.extend(vs)
        meshverts.extend(mv)
        faces.append(f)

    add_face(1, 0, _quad_z(0, 0, 64, 64, 0), cw_quad)  # floor, +Z
    add_face(1, 1, _quad_z(0, 0, 64, 64, 128, -1.0), [0, 1, 2, 0, 2, 3])  # ceiling facing down (CW from below)
    add_face(3, 0, [((0, 0, 16), (0, 0), (0, 0, 1)), ((0, 32, 16), (0, 1), (0, 0, 1)),
                    ((32, 0, 16), (1, 0), (0, 0, 1))], [0, 1, 2])  # mesh triangle, +Z
    patch = [((x, y, 32), (x / 64, y / 64), (0, 0, 1)) for y in (0, 32, 64) for x in (0, 32, 64)]
    add_face(2, 0, patch, [], size=(3, 3))
    add_face(1, 2, _quad_z(0, 0, 64, 64, 256, -1.0), [0, 1, 2, 0, 2, 3])  # sky
    add_face(1, 3, _quad_z(100, 0, 164, 64, 0), cw_quad)  # missing texture
    vert_arr = np.zeros(len(verts), VERTEX_DT)
    for i, (p, uv, n) in enumerate(verts):
        vert_arr[i]["pos"], vert_arr[i]["uv"], vert_arr[i]["normal"] = p, uv, n
        vert_arr[i]["color"] = (255, 255, 255, 255)
    face_arr = np.concatenate(faces)
    ents = (
        b'{\n"classname" "worldspawn"\n}\n'
        b'{\n"classname" "info_player_deathmatch"\n"origin" "32 16 8"\n"angle" "90"\n}\n'
        b'{\n"classname" "light"\n"origin" "32 32 100"\n"light" "300"\n"_color" "1 0.5 0.5"\n}\n'
    ) + b"\0"
    lumps = [b""] * 17
    lumps[0], lumps[1], lumps[10] = ents, textures.tobytes(), vert_arr.tobytes()
    lumps[11], lumps[13] = np.asarray(meshverts, "<i4").tobytes(), face_arr.tobytes()
    header_len = 8 + 17 * 8
    body, dir_ = b"", []
    for lump in lumps:
        dir_.append((header_len + len(body), len(lump)))
        body += lump + b"\0" * (-len(lump) % 4)
    return b"IBSP" + struct.pack("<i", 46) + b"".join(struct.pack("<ii", *d) for d in dir_) + body


SHADER = """
// test shaders
textures/test/fancy
{
    qer_editorimage textures/test/editor.tga
    {
        map $lightmap
        rgbGen identity
    }
    {
        map textures/test/other.png
        blendFunc filter
    }
}
textures/skies/sky
{
    surfaceparm sky
    surfaceparm noimpact
    q3map_sun 1 0.9 0.8 100 45 60
    skyparms - 512 -
}
"""


@pytest.fixture()
def tiny_pk3(tmp_path: Path) -> Path:
    p = tmp_path / "tiny.pk3"
    with zipfile.ZipFile(p, "w") as z:
        z.writestr("maps/tiny.bsp", write_test_bsp())
        z.writestr("textures/test/wall.jpg", _jpg((200, 30, 30)))
        z.writestr("textures/test/other.png", _png((20, 40, 220)))
        z.writestr("scripts/test.shader", SHADER)
    return p


def test_bsp_import(tiny_pk3: Path):
    conv = convert_bsp(tiny_pk3, "tiny", patch_level=6)
    s = conv.scene
    # 2 floor + 1 mesh + 72 patch (6x6 quads) on the wall texture, 2 on fancy, 2 on the missing one
    assert s.triangle_count == 2 + 1 + 72 + 2 + 2
    names = [m.name for m in s.materials]
    assert names == ["textures/test/wall", "textures/test/fancy", "textures/test/missing"]
    assert "textures/skies/sky" not in names and len(conv.sky_triangles) == 2
    assert conv.missing_textures == ["textures/test/missing"]
    wall, fancy, missing = s.materials
    assert wall.texture is not None and wall.texture[0, 0, 0] > 150 and wall.texture[0, 0, 2] < 80  # red jpg
    assert fancy.texture is not None and tuple(fancy.texture[0, 0, :3]) == (20, 40, 220)  # via the shader's map stage
    assert missing.texture is None and missing.base_color[:3] == (0.5, 0.5, 0.5)
    # units and axes: (x, y, z)_q3 -> (x, z, -y) * 0.0254
    lo, hi = s.bounds
    np.testing.assert_allclose(lo, [0.0, 0.0, -64 * UNIT], atol=1e-6)
    np.testing.assert_allclose(hi, [164 * UNIT, 128 * UNIT, 0.0], atol=1e-6)
    wall_mesh = next(m for m in s.meshes if m.material == 0)
    ys = np.unique(np.round(wall_mesh.positions[:, 1] / UNIT, 3))
    np.testing.assert_allclose(ys, [0.0, 16.0, 32.0])  # floor, mesh triangle, patch
    # every drawable face points up (+Z in Q3 is +Y) or, for the ceiling, down; all are CCW
    for m in s.meshes:
        np.testing.assert_allclose(np.linalg.norm(m.normals, axis=1), 1.0, atol=1e-5)
    assert _geometric_agreement(s) == 1.0
    np.testing.assert_allclose(next(m for m in s.meshes if m.material == 1).normals, [[0, -1, 0]] * 4, atol=1e-6)
    # spawn: eye 35 units above the origin, angle 90 (facing +Y_q3 = -Z) -> yaw 0
    (sp,) = s.spawn_points
    np.testing.assert_allclose(sp.position, np.array([32, 8 + 35, -16]) * UNIT, atol=1e-6)
    assert sp.yaw == pytest.approx(0.0)
    (light,) = s.point_lights
    np.testing.assert_allclose(light.position, np.array([32, 100, -32]) * UNIT, atol=1e-6)
    assert light.colour == pytest.approx((1.0, 0.5, 0.5))
    # sun from q3map_sun: azimuth 45, elevation 60, pointing down into the scene
    to_sun = np.array([math.cos(math.radians(60)) * math.cos(math.radians(45)),
                       math.cos(math.radians(60)) * math.sin(math.radians(45)), math.sin(math.radians(60))])
    np.testing.assert_allclose(s.sun.direction, -np.array([to_sun[0], to_sun[2], -to_sun[1]]), atol=1e-6)
    assert conv.stats["sky_faces"] == 1 and conv.stats["patches"] == 1


def test_bsp_from_loose_file_and_patch_level(tiny_pk3: Path, tmp_path: Path):
    bsp = tmp_path / "loose.bsp"
    bsp.write_bytes(write_test_bsp())
    s = load_bsp(bsp, pk3s=[tiny_pk3], patch_level=2)
    assert s.name == "loose" and s.triangle_count == 2 + 1 + 8 + 2 + 2


def test_bsp_errors(tiny_pk3: Path, tmp_path: Path):
    bad = tmp_path / "bad.bsp"
    bad.write_bytes(b"VBSP" + struct.pack("<i", 46) + b"\0" * 200)
    with pytest.raises(SceneFormatError, match="IBSP version 46"):
        load_bsp(bad)
    with pytest.raises(SceneNotFoundError, match="maps/nope.bsp"):
        load_bsp(tiny_pk3, "nope")
    with pytest.raises(SceneNotFoundError):
        load_bsp(tmp_path / "absent.pk3", "tiny")
    assert issubclass(SceneFormatError, RtpError) and issubclass(SceneNotFoundError, FileNotFoundError)


def test_conversion_helpers():
    assert q3_angle_to_yaw(90) == 0 and q3_angle_to_yaw(0) == -90 and q3_angle_to_yaw(180) == 90
    r1 = pbr_for_path("textures/base_wall/metalfloor_wall_10")
    assert r1[1] == 1.0 and r1 == pbr_for_path("textures/base_wall/metalfloor_wall_10")
    assert pbr_for_path("textures/gothic_block/blocks15")[0] > 0.7
    sh = parse_shaders(SHADER)
    assert sh["textures/test/fancy"].first_image() == "textures/test/other.png"
    assert "sky" in sh["textures/skies/sky"].surfaceparms


# -- glTF / OBJ through trimesh -------------------------------------------------------------------

def _textured_quad():
    import trimesh
    img = PIL.new("RGBA", (4, 4), (0, 0, 255, 255))
    for x in range(4):
        img.putpixel((x, 0), (255, 0, 0, 255))  # top row red
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)  # trimesh convention: bottom-left origin
    vis = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.PBRMaterial(
        baseColorTexture=img, roughnessFactor=0.25, metallicFactor=0.0))
    return trimesh, trimesh.Trimesh(v, f, visual=vis, process=False)


@pytest.mark.parametrize("ext", ["glb", "obj"])
def test_mesh_file(tmp_path: Path, ext: str):
    trimesh, mesh = _textured_quad()
    sc = trimesh.Scene()
    T = np.eye(4)
    T[:3, 3] = [2.0, 0.0, -1.0]
    sc.add_geometry(mesh, node_name="quad", transform=T)
    path = tmp_path / f"quad.{ext}"
    if ext == "obj":
        # OBJ has no scene graph: bake the transform and drop normals so the loader computes them
        m2 = mesh.copy()
        m2.apply_transform(T)
        m2.export(path, include_normals=False)
    else:
        sc.export(path)
    s = scenes.load_mesh_file(path)
    assert s.triangle_count == 2 and len(s.materials) == 1
    (m,) = s.meshes
    lo, hi = s.bounds
    np.testing.assert_allclose(lo, [2.0, 0.0, -1.0], atol=1e-6)
    np.testing.assert_allclose(hi, [3.0, 1.0, -1.0], atol=1e-6)
    np.testing.assert_allclose(m.normals, [[0, 0, 1]] * len(m.normals), atol=1e-6)
    tex = s.materials[0].texture
    assert tex is not None and tex.shape[2] == 4
    # the vertex at the top of the quad (y = 1) samples the image's top row (red) with top-left uvs
    top = m.uvs[m.positions[:, 1] > 0.5]
    assert np.allclose(top[:, 1], 0.0)
    row = int(np.clip(top[0, 1] * tex.shape[0], 0, tex.shape[0] - 1))
    assert tuple(tex[row, 0, :3]) == (255, 0, 0)
    if ext == "glb":
        assert s.materials[0].roughness == pytest.approx(0.25)


def test_a_16_bit_texture_keeps_its_values(tmp_path: Path):
    """A glTF's 16-bit greyscale texture is read by its values (Pillow's convert('RGBA') clipped it
    to white)."""
    from PIL import Image

    trimesh, mesh = _textured_quad()
    grey = np.array([[1000, 20000], [40000, 65535]], np.uint16)
    mesh.visual.material.baseColorTexture = Image.fromarray(grey)
    mesh.export(tmp_path / "grey16.glb")
    tex = scenes.load_mesh_file(tmp_path / "grey16.glb").materials[0].texture
    assert tex is not None
    np.testing.assert_array_equal(np.unique(tex[..., 0]), np.round(np.sort(grey.ravel()) / 257))
    assert (tex[..., 0] == tex[..., 2]).all() and (tex[..., 3] == 255).all()


def test_a_mesh_files_spawn_point_is_not_inside_an_object(tmp_path: Path, caplog: pytest.LogCaptureFixture):
    """A mesh file has no spawn points: the loader puts one at the centre of its bounds, eye height over their
    bottom. A room with a ball at its centre put it inside the ball, the flood fill flooded the ball's inside, and
    every viewpoint of `rtp capture --scene room.glb` looked at the ball from within. The spawn point moves to
    the room's free space, its voxel nearest the centre at that height; a room whose centre is free keeps it there."""
    import trimesh

    from rtp.capture.viewpoints import free_space

    room = trimesh.creation.box((4.0, 3.0, 4.0))  # centred on the origin: the bottom at y = -1.5
    trimesh.Scene([room, trimesh.creation.icosphere(radius=1.0)]).export(tmp_path / "ball.glb")
    trimesh.Scene([room]).export(tmp_path / "empty.glb")
    with caplog.at_level(logging.INFO, logger="rtp.capture"):
        ball = scenes.load_mesh_file(tmp_path / "ball.glb")
    (sp,) = ball.spawn_points
    assert np.linalg.norm(sp.position) > 1.2 and sp.position[1] == pytest.approx(0.1, abs=1e-6)  # out of the ball
    assert "the centre of its bounds lies in a free region" in caplog.text
    _, grid, reach, _ = free_space(ball)
    inside = grid.centre(np.flatnonzero(reach))
    assert (np.linalg.norm(inside, axis=1) > 1.0).all() and len(inside) * grid.voxel ** 3 > 20.0  # the room
    (sp,) = scenes.load_mesh_file(tmp_path / "empty.glb").spawn_points
    np.testing.assert_allclose(sp.position, (0.0, 0.1, 0.0), atol=1e-6)


def _boxes(trimesh: Any, *boxes: tuple[tuple[float, float, float], tuple[float, float, float]]) -> Any:
    """Solid boxes ``(extents, centre)`` as one trimesh mesh (a level's slabs: floors, walls, ceilings)."""
    parts = []
    for ext, centre in boxes:
        b = trimesh.creation.box(ext)
        b.apply_translation(centre)
        parts.append(b)
    return trimesh.util.concatenate(parts)


def test_a_mesh_files_spawn_point_lies_in_its_enclosed_space(tmp_path: Path):
    """The spawn search counted the free space over the bounds' bottom for a floor and took the largest free
    region: the empty corners of the bounds around a closed level, and the space over its roof. A dome (an
    inward-facing sphere, radius 20) spawned outside it at (6.7, -18.4, 6.7), and an L-shaped corridor in the empty
    square its legs enclose, where every viewpoint then looked at the corridor from outside. Free space over
    nothing drawn is outside the level, and a region lying over another one is that one's outside: both now
    spawn inside, and their flood stays there. A sealed shed at the centre of an open ground keeps the spawn point
    on the ground (the largest region), and a small building with a far prop widening its bounds spawns inside it."""
    import trimesh

    from rtp.capture.viewpoints import free_space

    dome = trimesh.creation.icosphere(subdivisions=3, radius=20.0)
    dome.invert()  # (the faces toward the centre: a closed, inward-facing level)
    dome.export(tmp_path / "dome.glb")
    t = 0.2  # legs 2 m wide, 3 m high: x in [0, 30], z in [0, 2], and x in [28, 30], z in [0, 30]
    _boxes(trimesh, ((30, t, 2), (15, -t / 2, 1)), ((30, t, 2), (15, 3 + t / 2, 1)), ((2, t, 28), (29, -t / 2, 16)),
           ((2, t, 28), (29, 3 + t / 2, 16)), ((30, 3, t), (15, 1.5, -t / 2)), ((28, 3, t), (14, 1.5, 2 + t / 2)),
           ((t, 3, 2), (-t / 2, 1.5, 1)), ((t, 3, 30), (30 + t / 2, 1.5, 15)), ((t, 3, 28), (28 - t / 2, 1.5, 16)),
           ((2, 3, t), (29, 1.5, 30 + t / 2))).export(tmp_path / "corridor.glb")
    shed = trimesh.creation.box((3.0, 2.5, 3.0))
    shed.invert()
    shed.apply_translation((0, 1.25, 0))
    trimesh.util.concatenate([_boxes(trimesh, ((60, 0.2, 60), (0, -0.1, 0))), shed]).export(tmp_path / "ground.glb")
    house = trimesh.creation.box((6.0, 3.0, 6.0))
    house.invert()
    house.apply_translation((10, 1.5, 10))
    trimesh.util.concatenate([house, _boxes(trimesh, ((1, 12, 1), (-20, 6, -20)))]).export(tmp_path / "house.glb")

    scene = scenes.load_mesh_file(tmp_path / "dome.glb")
    (sp,) = scene.spawn_points
    assert np.linalg.norm(sp.position) < 19.0
    _, grid, reach, _ = free_space(scene, voxel=0.5)
    assert reach.sum() > 1000 and (np.linalg.norm(grid.centre(np.flatnonzero(reach)), axis=1) < 20.0).all()

    scene = scenes.load_mesh_file(tmp_path / "corridor.glb")
    (sp,) = scene.spawn_points
    x, y, z = sp.position
    assert 0 < y < 3 and ((0 < x < 30 and 0 < z < 2) or (28 < x < 30 and 0 < z < 30)), sp.position
    _, grid, reach, _ = free_space(scene)
    x, y, z = grid.centre(np.flatnonzero(reach)).T
    assert reach.sum() > 1000 and (((z < 2.1) | (x > 27.9)) & (y > -0.1) & (y < 3.1)).all()

    (sp,) = scenes.load_mesh_file(tmp_path / "ground.glb").spawn_points
    assert max(abs(sp.position[0]), abs(sp.position[2])) > 1.5 and sp.position[1] == pytest.approx(1.4)  # not in the shed
    (sp,) = scenes.load_mesh_file(tmp_path / "house.glb").spawn_points
    assert max(abs(sp.position[0] - 10), abs(sp.position[2] - 10)) < 3 and 0 < sp.position[1] < 3  # in the house


def test_a_mesh_file_in_other_units_or_z_up_loads_with_a_warning(tmp_path: Path, caplog: pytest.LogCaptureFixture):
    """Units and axes are taken as given: a level modelled in centimetres loaded 100 times too large, and a Z-up
    one on its side, without a word. Both load as they are, with a warning naming the cause and the fix; the
    level in metres, Y up, loads without one."""
    import trimesh

    t = 0.2  # a 20 x 4 x 12 m hall of slabs: floor, ceiling, four walls, and a dividing wall with a doorway
    hall = _boxes(trimesh, ((20, t, 12), (0, -t / 2, 0)), ((20, t, 12), (0, 4 + t / 2, 0)),
                  ((20, 4, t), (0, 2, -6 - t / 2)), ((20, 4, t), (0, 2, 6 + t / 2)), ((t, 4, 12), (-10 - t / 2, 2, 0)),
                  ((t, 4, 12), (10 + t / 2, 2, 0)), ((t, 4, 5), (0, 2, -3.5)), ((t, 4, 5), (0, 2, 3.5)))
    hall.export(tmp_path / "hall.glb")
    cm = hall.copy()
    cm.apply_scale(100.0)
    cm.export(tmp_path / "hall_cm.glb")
    km = hall.copy()
    km.apply_scale(0.001)
    km.export(tmp_path / "hall_km.glb")
    zup = hall.copy()
    zup.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, (1, 0, 0)))  # Y up -> Z up
    zup.export(tmp_path / "hall_zup.glb")

    def said(name: str) -> list[str]:
        caplog.clear()
        with caplog.at_level("WARNING", logger="rtp"):
            scenes.load_mesh_file(tmp_path / name)
        return [r.getMessage() for r in caplog.records]

    assert said("hall.glb") == []
    for name, spans in (("hall_cm.glb", "2040 x 440 x 1240 m"), ("hall_km.glb", "0.0204 x 0.0044 x 0.0124 m")):
        (units, *_) = said(name)
        assert units.startswith(f"{name}: its geometry spans {spans}, implausible for a level in metres")
        assert "export the level in metres, Y up" in units
    (axes,) = said("hall_zup.glb")
    assert axes.startswith("hall_zup.glb: it looks modelled with Z up (it spans 20.4 x 12.4 x 4.4 m, thinnest along Z")
    assert "export the level in metres, Y up" in axes


def test_mesh_file_errors(tmp_path: Path):
    with pytest.raises(SceneNotFoundError):
        scenes.load_mesh_file(tmp_path / "none.glb")


# -- splits, cache and the by-name API ------------------------------------------------------------

def test_splits_shipped_copy():
    s = load_splits()
    assert set(s) == {"train", "validation", "test"}
    assert "20kdm2" in s["test"] and "oa_dm5" in s["test"] and "kaos" in s["validation"]
    assert not set(s["train"]) & set(s["test"])
    shared = Path("/work/shared/scenes.yaml")
    if shared.is_file():
        assert load_splits(shared) == s


def test_splits_reject_unlisted(tmp_path: Path):
    with pytest.raises(UnlistedMapError, match="hydronex"):
        scene_by_name("hydronex", tmp_path)  # in the packages, but not in scenes.yaml
    with pytest.raises(UnlistedMapError):
        scene_by_name("oa_dm5", tmp_path, split="train")  # a test map is not a training map
    with pytest.raises(UnlistedMapError, match=r"did you mean 20kdm2\?"):  # a typo gets its neighbours
        scene_by_name("20kdm", tmp_path)
    with pytest.raises(UnlistedMapError):
        scenes.fetch(tmp_path, ["hydronex"])  # refused before any download
    with pytest.raises(SceneNotFoundError, match="rtp scenes fetch"):
        scene_by_name("oa_dm5", tmp_path)  # listed, but nothing fetched
    bad = tmp_path / "bad.yaml"
    bad.write_text("train: [a]\nvalidation: [a]\ntest: []\n")
    with pytest.raises(SceneFormatError, match="both"):
        load_splits(bad)
    bad.write_text("train: [a]\n")
    with pytest.raises(SceneFormatError):
        load_splits(bad)


def test_cache_round_trip(tmp_path: Path):
    s = procedural(2, rooms=(1, 2))
    sky = np.arange(18, dtype=np.float32).reshape(2, 3, 3)
    save_scene_npz(tmp_path / "s.npz", s, sky, {"triangles": s.triangle_count})
    s2, sky2, stats = load_scene_npz(tmp_path / "s.npz")
    for a, b in zip(_scene_arrays(s), _scene_arrays(s2)):
        assert np.array_equal(a, b)
    assert s2.point_lights == s.point_lights and s2.spawn_points == s.spawn_points and s2.sun == s.sun
    assert [m.alpha_cutoff for m in s2.materials] == [m.alpha_cutoff for m in s.materials]
    assert np.array_equal(sky, sky2) and stats["triangles"] == s.triangle_count


def test_scene_by_name_converts_once_and_caches(tmp_path: Path):
    # a fake fetched cache whose archive holds our tiny map under a listed name
    cache = tmp_path / "cache"
    (cache / "pk3").mkdir(parents=True)
    with zipfile.ZipFile(cache / "pk3" / "x.pk3", "w") as z:
        z.writestr("maps/oa_dm1.bsp", write_test_bsp())
        z.writestr("textures/test/wall.jpg", _jpg((200, 30, 30)))
        z.writestr("textures/test/other.png", _png((20, 40, 220)))
        z.writestr("scripts/test.shader", SHADER)
    index = {"version": 1, "maps": {"oa_dm1": "pk3/x.pk3"}, "groups": {"x": ["pk3/x.pk3"]}}
    (cache / "index.json").write_text(json.dumps(index))
    s1 = scene_by_name("oa_dm1", cache)
    assert list((cache / "converted").glob("oa_dm1.v*.npz"))
    s2 = scene_by_name("oa_dm1", cache, split="train")
    assert s1.triangle_count == s2.triangle_count == 79
    assert len(scenes.scene_blockers("oa_dm1", cache)) == 2


def test_fetch_cli_rejects_unlisted(tmp_path: Path, capsys):
    from rtp.cli import main as rtp_main

    assert rtp_main(["scenes", "fetch", "--cache-dir", str(tmp_path), "--map", "hydronex", "--no-progress"]) == 2
    assert "hydronex" in capsys.readouterr().err
    assert not (tmp_path / "debs").exists()  # nothing was downloaded


# -- pk3 archives and shader scripts --------------------------------------------------------------

def test_a_pk3_member_that_unpacks_to_more_than_a_level_may_is_refused_unread(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A zip bomb in an archive someone handed over (a few MB of deflated zeros that unpack to gigabytes, as a
    texture or a BSP): Pk3Set.read unpacked the whole member into memory. A member whose size, which zipfile
    holds it to, is over ``MAX_MEMBER_BYTES`` is a SceneFormatError naming it and the archive, nothing unpacked;
    one at the limit is read. (The limit is lowered here: a real bomb would take the test's memory.)"""
    from rtp.capture.scenes import _pk3

    monkeypatch.setattr(_pk3, "MAX_MEMBER_BYTES", 1000)
    bomb = tmp_path / "bomb.pk3"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("maps/bomb.bsp", bytes(1001))
        z.writestr("textures/ok.jpg", bytes(1000))
    with Pk3Set([bomb]) as pk3:
        with pytest.raises(SceneFormatError, match=r"maps/bomb.bsp in .*bomb.pk3 unpacks to 0 MiB, more than a pk3 "
                                                   r"member of a level may \(0 MiB\): not read"):
            pk3.read("maps/bomb.bsp")
        assert pk3.read("textures/ok.jpg") == bytes(1000)


def test_pk3_archives(tmp_path: Path):
    """Pk3Set: a missing archive is SceneNotFoundError, a file that is not a zip SceneFormatError, a
    path no archive holds SceneNotFoundError; paths are case-insensitive, the first archive holding one
    wins, directory entries are not files; ``with`` closes the archives; a damaged member (bad CRC,
    broken deflate stream) is SceneFormatError naming it, not zipfile.BadZipFile or zlib.error."""
    first, second = tmp_path / "first.pk3", tmp_path / "second.pk3"
    with zipfile.ZipFile(first, "w") as z:
        z.writestr(zipfile.ZipInfo("Textures/"), b"")
        z.writestr("Textures/Wall.JPG", b"first")
    with zipfile.ZipFile(second, "w") as z:
        z.writestr("textures/wall.jpg", b"second")
        z.writestr("textures/only.jpg", b"only")
    with pytest.raises(SceneNotFoundError, match="pk3 archive not found: .*absent.pk3"):
        Pk3Set([first, tmp_path / "absent.pk3"])
    junk = tmp_path / "junk.pk3"
    junk.write_bytes(b"PK\x03\x04 cut short")
    with pytest.raises(SceneFormatError, match=r"junk.pk3 is not a pk3 \(zip\) archive"):
        Pk3Set([junk])
    with Pk3Set([first, second]) as pk3:
        assert pk3.names() == ["textures/only.jpg", "textures/wall.jpg"] and "textures/" not in pk3
        assert pk3.read("TEXTURES/WALL.jpg") == b"first" and pk3.archive_of("textures/wall.jpg") == first
        assert pk3.read("textures/only.jpg") == b"only"
        # a Windows tool's backslashes, as the index reads an entry's (they were not found)
        assert "textures\\only.jpg" in pk3 and pk3.read("Textures\\Only.jpg") == b"only"
        assert pk3.archive_of("textures\\wall.jpg") == first and pk3.names("textures\\o") == ["textures/only.jpg"]
        with pytest.raises(SceneNotFoundError, match="textures/gone.jpg is not in any of"):
            pk3.read("textures/gone.jpg")
    assert all(z.fp is None for z in pk3._zips)  # closed
    for compression in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
        damaged = tmp_path / f"damaged{compression}.pk3"
        with zipfile.ZipFile(damaged, "w", compression) as z:
            z.writestr("scripts/a.shader", "textures/a\n{\n surfaceparm nodraw\n}\n" * 20)
        damage_zip_member(damaged, "scripts/a.shader")
        with Pk3Set([damaged]) as pk3, pytest.raises(SceneFormatError, match=r"scripts/a.shader in .*damaged\d.pk3 is damaged"):
            pk3.read("scripts/a.shader")



def test_archives_opened_before_a_refused_one_are_closed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Pk3Set refused a missing or broken archive with the archives it had opened before it left open (their files
    held until the process ended or Python collected them); convert_bsp refused a damaged map member the same way
    once its set was made. Now every refusal closes what was opened."""
    from rtp.capture.scenes import _pk3

    opened: list[zipfile.ZipFile] = []

    class Recorded(zipfile.ZipFile):
        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            opened.append(self)

    monkeypatch.setattr(_pk3.zipfile, "ZipFile", Recorded)
    good = tmp_path / "good.pk3"
    with zipfile.ZipFile(good, "w") as z:
        z.writestr("maps/a.bsp", write_test_bsp())
        z.writestr("maps/b.bsp", write_test_bsp())
    junk = tmp_path / "junk.pk3"
    junk.write_bytes(b"PK\x03\x04 cut short")
    for second, error in ((tmp_path / "absent.pk3", SceneNotFoundError), (junk, SceneFormatError)):
        with pytest.raises(error):
            Pk3Set([good, second])
        assert opened and all(z.fp is None for z in opened), second  # closed
        opened.clear()
    with pytest.raises(SceneFormatError, match="holds 2 maps"):
        convert_bsp(good)
    assert len(opened) == 1 and opened[0].fp is None
    damage_zip_member(good, "maps/a.bsp")
    opened.clear()
    with pytest.raises(SceneFormatError, match=r"maps/a.bsp in .*good.pk3 is damaged"):
        convert_bsp(good, "a")
    assert len(opened) == 1 and opened[0].fp is None


SHADER_DETAILS = """
textures/test/chrome
{
    {
        map textures/test/chrome.jpg
        tcGen environment
    }
    {
        map textures/test/chrome2.jpg
        tcgen environmentModel
    }
}
textures/test/mixed
{
    {
        map textures/test/chrome.jpg
        tcGen environment
    }
    {
        map textures/test/base.jpg
    }
}
textures/test/anim
{
    {
        animMap 5 textures/test/frame1.jpg textures/test/frame2.jpg
        blendFunc GL_ONE GL_ZERO
    }
}
textures/test/glass
{
    {
        map textures/test/glass.jpg
        blendFunc GL_DST_COLOR GL_ONE
    }
}
textures/test/bare
{
    surfaceparm nomarks
}
textures/test/sloppy
{
    q3map_sun 1 1 one 100 45 60
    q3map_surfacelight lots
    q3map_lightRGB 1 half 1
    {
        map textures/test/sloppy.jpg
        {
            map textures/test/nested.jpg
        }
    }
}
{
    qer_editorimage textures/test/nameless.jpg
}
textures/test/last
{
}
}
textures/test/after
{
}
"""


def test_shader_script_details(caplog: pytest.LogCaptureFixture):
    """What the converter reads of a shader: environment-mapped stages come last when choosing the
    image (first of them if all are), ``animMap``'s first frame, explicit ``blendFunc`` factors; a
    shader with no stages or an opaque GL_ONE GL_ZERO stage is not blended-only; malformed numbers
    are ignored (the rest of the shader kept), blocks nested too deep and blocks without a name are
    skipped, and an unbalanced '}' ends the script (logged)."""
    with caplog.at_level("DEBUG", logger="rtp"):
        sh = parse_shaders(SHADER_DETAILS)
    assert list(sh) == ["textures/test/chrome", "textures/test/mixed", "textures/test/anim", "textures/test/glass",
                        "textures/test/bare", "textures/test/sloppy", "textures/test/last"]
    assert any("unbalanced '}'" in r.getMessage() for r in caplog.records)
    chrome = sh["textures/test/chrome"]
    assert [s.tcgen_environment for s in chrome.stages] == [True, True]
    assert chrome.first_image() == "textures/test/chrome.jpg"
    assert sh["textures/test/mixed"].first_image() == "textures/test/base.jpg"
    (anim,) = sh["textures/test/anim"].stages
    assert anim.map == "textures/test/frame1.jpg" and anim.blend == ("gl_one", "gl_zero")
    assert not sh["textures/test/anim"].is_additive_only()
    assert sh["textures/test/glass"].stages[0].blend == ("gl_dst_color", "gl_one")
    assert sh["textures/test/glass"].is_additive_only()
    bare = sh["textures/test/bare"]
    assert bare.stages == [] and not bare.is_additive_only() and bare.first_image() is None
    sloppy = sh["textures/test/sloppy"]
    assert (sloppy.sun, sloppy.surface_light, sloppy.light_rgb) == (None, 0.0, None)
    assert [s.map for s in sloppy.stages] == ["textures/test/sloppy.jpg"]


# -- glTF / OBJ / PLY materials and geometry ------------------------------------------------------

QUAD_V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
QUAD_F = np.array([[0, 1, 2], [0, 2, 3]])
QUAD_UV = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)


def test_mesh_file_materials(tmp_path: Path):
    """Materials from the file: glTF emission and alpha MASK (its cutoff, 0.5 by default), an OBJ
    diffuse colour and Phong exponent (roughness sqrt(2 / (n + 2))), vertex and face colours as their
    mean; a geometry without texture coordinates gets zero uvs."""
    import trimesh
    PBR = trimesh.visual.material.PBRMaterial

    def textured(material):
        return trimesh.Trimesh(QUAD_V, QUAD_F, visual=trimesh.visual.TextureVisuals(uv=QUAD_UV, material=material),
                               process=False)

    files = {
        "glow.glb": textured(PBR(baseColorFactor=[0.2, 0.4, 0.6, 1.0], emissiveFactor=[1.0, 0.5, 0.0], alphaMode="MASK",
                                 alphaCutoff=0.3)),
        "mask.glb": textured(PBR(baseColorFactor=[51, 102, 153, 255], alphaMode="MASK")),
        "kd.obj": textured(trimesh.visual.material.SimpleMaterial(diffuse=[51, 102, 153, 255], glossiness=10.0)),
        "vertex.ply": trimesh.Trimesh(QUAD_V, QUAD_F, vertex_colors=[[255, 0, 0, 255]] * 2 + [[0, 0, 255, 255]] * 2,
                                      process=False),
        "face.ply": trimesh.Trimesh(QUAD_V, QUAD_F, face_colors=[[255, 0, 0, 255], [0, 255, 0, 255]], process=False),
    }
    mats = {}
    for name, mesh in files.items():
        mesh.export(tmp_path / name)
        scene = scenes.load_mesh_file(tmp_path / name)
        mats[name] = scene.materials[0]
        if name.endswith(".ply"):
            np.testing.assert_array_equal(scene.meshes[0].uvs, 0.0)
    glow, mask, kd = mats["glow.glb"], mats["mask.glb"], mats["kd.obj"]
    assert glow.base_color == pytest.approx((0.2, 0.4, 0.6, 1.0)) and glow.emissive == pytest.approx((1.0, 0.5, 0.0))
    assert glow.alpha_cutoff == pytest.approx(0.3) and mask.alpha_cutoff == 0.5
    assert mask.base_color == pytest.approx((0.2, 0.4, 0.6, 1.0)) and mask.emissive == (0.0, 0.0, 0.0)
    assert kd.texture is None and kd.base_color == pytest.approx((0.2, 0.4, 0.6, 1.0))
    assert kd.roughness == pytest.approx(math.sqrt(2.0 / 12.0))
    assert mats["vertex.ply"].base_color == pytest.approx((0.5, 0.0, 0.5, 1.0))
    assert mats["face.ply"].base_color == pytest.approx((0.5, 0.5, 0.0, 1.0))


def test_an_mtl_diffuse_colour_multiplies_its_texture(tmp_path: Path) -> None:
    """An MTL material with a ``map_Kd`` loaded with a white base colour, its ``Kd`` dropped: a red-tinted texture
    drew untinted, where Blender and trimesh's own viewer multiply the two. Now the base colour is the ``Kd`` (the
    renderer multiplies it with the texture); a material with a texture and no ``Kd`` keeps the texture alone, not
    trimesh's 0.4 grey default diffuse; one with a ``Kd`` and no texture is as before."""
    PIL.fromarray(np.full((4, 4, 3), 200, np.uint8)).save(tmp_path / "t.png")
    obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nusemtl {}\nf 1/1/1 2/2/1 3/3/1\n"
    (tmp_path / "m.mtl").write_text("newmtl tinted\nKd 1.0 0.6 0.2\nmap_Kd t.png\n"
                                    "newmtl plain\nmap_Kd t.png\n"
                                    "newmtl flat\nKd 0.2 0.4 0.6\n")
    got = {}
    for name in ("tinted", "plain", "flat"):
        (tmp_path / f"{name}.obj").write_text(obj.format(name))
        got[name] = scenes.load_mesh_file(tmp_path / f"{name}.obj").materials[0]
    assert got["tinted"].texture is not None and got["plain"].texture is not None and got["flat"].texture is None
    assert got["tinted"].base_color == pytest.approx((1.0, 0.6, 0.2, 1.0), abs=1 / 255)
    assert got["plain"].base_color == (1.0, 1.0, 1.0, 1.0)
    assert got["flat"].base_color == pytest.approx((0.2, 0.4, 0.6, 1.0), abs=1 / 255)
    np.testing.assert_array_equal(got["tinted"].texture, got["plain"].texture)

def test_mesh_file_geometry_fallbacks(tmp_path: Path, caplog: pytest.LogCaptureFixture):
    """A mirroring node transform flips the winding so triangles still face their normals; normals
    stored as zero vectors are recomputed; a texture that fails to decode leaves the material
    untextured (with a warning); geometry without faces (a point cloud) is skipped."""
    trimesh, mesh = _textured_quad()
    sc = trimesh.Scene()
    sc.add_geometry(trimesh.Trimesh(QUAD_V, QUAD_F, process=False), node_name="mirrored",
                    transform=np.diag([-1.0, 1.0, 1.0, 1.0]))
    sc.add_geometry(trimesh.PointCloud(QUAD_V + 5.0), node_name="points")
    sc.export(tmp_path / "mirror.glb")
    s = scenes.load_mesh_file(tmp_path / "mirror.glb")
    (m,) = s.meshes
    p = m.positions[m.indices.astype(np.int64)]
    geometric = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    np.testing.assert_allclose(geometric / np.linalg.norm(geometric, axis=1, keepdims=True), [[0, 0, 1]] * 2, atol=1e-6)
    np.testing.assert_allclose(m.normals, [[0, 0, 1]] * 4, atol=1e-6)
    assert s.bounds[1][0] == pytest.approx(0.0)  # the quad, mirrored; no points
    trimesh.Trimesh(QUAD_V, QUAD_F, vertex_normals=np.zeros((4, 3)), process=False).export(tmp_path / "zero.glb")
    np.testing.assert_allclose(scenes.load_mesh_file(tmp_path / "zero.glb").meshes[0].normals, [[0, 0, 1]] * 4, atol=1e-6)
    glb = bytearray(mesh.export(file_type="glb"))
    at = glb.find(b"IDAT")  # the PNG's pixel data, overwritten in place: it opens, but does not decode
    n = struct.unpack(">I", glb[at - 4 : at])[0]
    glb[at + 4 : at + 4 + n] = b"\0" * n
    (tmp_path / "badtex.glb").write_bytes(bytes(glb))
    with caplog.at_level("WARNING", logger="rtp"):
        bad = scenes.load_mesh_file(tmp_path / "badtex.glb")
    assert bad.materials[0].texture is None and bad.triangle_count == 2
    assert any("could not convert texture image" in r.getMessage() for r in caplog.records)


def test_mesh_file_format_errors(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A file without triangles or one trimesh cannot read is SceneFormatError; without trimesh,
    loading says what to install."""
    import trimesh
    trimesh.PointCloud(QUAD_V).export(tmp_path / "points.ply")
    (tmp_path / "lines.obj").write_text("v 0 0 0\nv 1 0 0\nl 1 2\n")
    for name in ("points.ply", "lines.obj"):
        with pytest.raises(SceneFormatError, match=f"{name} contains no triangles"):
            scenes.load_mesh_file(tmp_path / name)
    (tmp_path / "junk.glb").write_bytes(b"glTF junk")
    with pytest.raises(SceneFormatError, match="trimesh could not read .*junk.glb"):
        scenes.load_mesh_file(tmp_path / "junk.glb")
    monkeypatch.setitem(sys.modules, "trimesh", None)
    with pytest.raises(ImportError, match=r"needs trimesh and pillow: pip install 'rtp\[capture\]'"):
        scenes.load_mesh_file(tmp_path / "junk.glb")


def test_an_obj_texture_or_material_library_that_cannot_be_read_is_dropped_with_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
):
    """An MTL's ``map_Kd`` naming a missing image left the material untextured without a word (trimesh logs
    it at DEBUG), and a missing ``.mtl`` gave trimesh's grey 2x2 placeholder texture, silently: both are
    dropped with a warning naming the file, the material untextured (the MTL's Kd kept)."""
    obj = "mtllib {}\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nusemtl red\nf 1/1 2/2 3/3\n"
    (tmp_path / "lost.obj").write_text(obj.format("lost.mtl"))
    (tmp_path / "lost.mtl").write_text("newmtl red\nKd 1 0 0\nmap_Kd missing.png\n")
    with caplog.at_level("WARNING", logger="rtp"):
        (mat,) = scenes.load_mesh_file(tmp_path / "lost.obj").materials
    assert mat.texture is None and mat.base_color == pytest.approx((1.0, 0.0, 0.0, 1.0))
    assert any("lost.mtl: texture missing.png of material 'red' cannot be read" in r.getMessage() for r in caplog.records)
    caplog.clear()
    (tmp_path / "nolib.obj").write_text(obj.format("absent.mtl"))
    with caplog.at_level("WARNING", logger="rtp"):
        (mat,) = scenes.load_mesh_file(tmp_path / "nolib.obj").materials
    assert mat.texture is None and mat.base_color == pytest.approx((0.8, 0.8, 0.8, 1.0))  # not the placeholder
    assert any("nolib.obj: its material library" in r.getMessage() and "absent.mtl cannot be read" in r.getMessage()
               for r in caplog.records)
    caplog.clear()
    PIL.new("RGBA", (4, 4), (0, 0, 255, 255)).save(tmp_path / "blue.png")
    (tmp_path / "lost.mtl").write_text("newmtl red\nKd 1 0 0\nmap_Kd blue.png\n")
    with caplog.at_level("WARNING", logger="rtp"):
        (mat,) = scenes.load_mesh_file(tmp_path / "lost.obj").materials
    assert mat.texture is not None and tuple(mat.texture[0, 0]) == (0, 0, 255, 255) and not caplog.records


def _gltf_quad(uri: str) -> dict:
    """A glTF of one textured unit quad whose base colour image is the file ``uri`` (its buffer embedded)."""
    import base64

    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
    buf = pos.tobytes() + np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32).tobytes() \
        + np.array([0, 1, 2, 0, 2, 3], np.uint16).tobytes()
    return {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "scene": 0, "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
            "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
            "textures": [{"source": 0}], "images": [{"uri": uri}],
            "buffers": [{"byteLength": len(buf),
                         "uri": "data:application/octet-stream;base64," + base64.b64encode(buf).decode()}],
            "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48},
                            {"buffer": 0, "byteOffset": 48, "byteLength": 32},
                            {"buffer": 0, "byteOffset": 80, "byteLength": 12}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0],
                           "max": [1, 1, 0]},
                          {"bufferView": 1, "componentType": 5126, "count": 4, "type": "VEC2"},
                          {"bufferView": 2, "componentType": 5123, "count": 6, "type": "SCALAR"}]}


def test_an_absolute_uri_is_not_read_where_it_points_but_beside_the_file(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
):
    """A scene someone else made may name any file of this machine by an absolute path (a glTF image or buffer
    URI ``/home/me/.ssh/id_rsa``, an OBJ's ``mtllib /etc/...``): the loader read it, into the scene's textures or
    geometry (and on into a capture someone shares). An absolute name is a path of the machine the scene was made
    on, as docs/scenes.md says: looked for by its last part beside the file (found there: read; not: a warning
    naming it, the material untextured), never where it points."""
    elsewhere = tmp_path / "home" / "me"
    elsewhere.mkdir(parents=True)
    PIL.new("RGBA", (4, 4), (255, 0, 0, 255)).save(elsewhere / "secret.png")
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "abs.gltf").write_text(json.dumps(_gltf_quad(str(elsewhere / "secret.png"))))
    obj = "mtllib {}\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl red\nf 1 2 3\n"
    (elsewhere / "room.mtl").write_text("newmtl red\nKd 1 0 0\n")
    (tmp_path / "models" / "abs.obj").write_text(obj.format(elsewhere / "room.mtl"))
    with caplog.at_level("WARNING", logger="rtp"):
        (mat,) = scenes.load_mesh_file(tmp_path / "models" / "abs.gltf").materials
        (lib,) = scenes.load_mesh_file(tmp_path / "models" / "abs.obj").materials
    assert mat.texture is None and "secret.png" in caplog.text, caplog.text
    assert lib.base_color != pytest.approx((1.0, 0.0, 0.0, 1.0)) and "room.mtl" in caplog.text
    PIL.new("RGBA", (4, 4), (0, 0, 255, 255)).save(tmp_path / "models" / "secret.png")  # its name, beside the file
    (mat,) = scenes.load_mesh_file(tmp_path / "models" / "abs.gltf").materials
    assert mat.texture is not None and tuple(mat.texture[0, 0]) == (0, 0, 255, 255)


def test_a_gltfs_external_texture_is_found_where_it_names_it_or_named_in_a_warning(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
):
    """trimesh reads nothing outside the file's folder: a glTF's texture in ``../textures/`` (a common layout)
    was dropped without a word, as were a percent-encoded URI (``my%20wall.png``, how exporters write a name
    with a space) and a missing image (trimesh logs them at DEBUG). The first two are read now; a file that
    is not there is a warning naming it, the material untextured."""
    (tmp_path / "models").mkdir()
    (tmp_path / "textures").mkdir()
    PIL.new("RGBA", (4, 4), (255, 0, 0, 255)).save(tmp_path / "textures" / "red.png")
    PIL.new("RGBA", (4, 4), (0, 0, 255, 255)).save(tmp_path / "models" / "my wall.png")
    cases = {"up": ("../textures/red.png", (255, 0, 0, 255)), "space": ("my%20wall.png", (0, 0, 255, 255)),
             "missing": ("missing.png", None)}
    for name, (uri, texel) in cases.items():
        (tmp_path / "models" / f"{name}.gltf").write_text(json.dumps(_gltf_quad(uri)))
        caplog.clear()
        with caplog.at_level("WARNING", logger="rtp"):
            (mat,) = scenes.load_mesh_file(tmp_path / "models" / f"{name}.gltf").materials
        if texel is None:
            assert mat.texture is None
            assert [r.getMessage() for r in caplog.records] == [
                f"{tmp_path / 'models' / 'missing.gltf'}: the file missing.png it names cannot be read (no such "
                "file): what uses it is dropped (a texture: the material untextured)"]
        else:
            assert mat.texture is not None and tuple(mat.texture[0, 0]) == texel, name
            assert not caplog.records


def test_a_gltfs_metallic_roughness_and_emissive_textures_and_emissive_strength_scale_their_factors(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """The scene holds one roughness, metalness and emission a material, and the loader took the glTF factors
    alone: a material with a metallic-roughness texture (its factors left at 1, as Blender writes them) drew fully
    metallic and fully rough, one with an emissive texture glowed all over at its factor, and one with
    ``KHR_materials_emissive_strength`` 4 glowed a quarter as bright. The factors are multiplied by the textures'
    means (roughness the green channel, metalness the blue, as stored; emission decoded from sRGB) and by the
    strength; a strength that no name of the file holds alone is not applied, with a warning."""
    mr = np.zeros((4, 4, 3), np.uint8)
    mr[..., 1] = 51  # roughness 0.2
    mr[:, :2, 2] = 255  # half of it metal
    glow = np.zeros((4, 4, 3), np.uint8)
    glow[:2, :, 0] = 255  # the top half red, the rest black
    PIL.fromarray(mr).save(tmp_path / "mr.png")
    PIL.fromarray(glow).save(tmp_path / "glow.png")
    doc = _gltf_quad("mr.png")
    doc["images"].append({"uri": "glow.png"})
    doc["textures"].append({"source": 1})
    doc["extensionsUsed"] = ["KHR_materials_emissive_strength"]
    doc["materials"] = [{"name": "lamp", "pbrMetallicRoughness": {"metallicRoughnessTexture": {"index": 0}},
                         "emissiveFactor": [1.0, 1.0, 1.0], "emissiveTexture": {"index": 1},
                         "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}}]
    (tmp_path / "lamp.gltf").write_text(json.dumps(doc))
    (mat,) = scenes.load_mesh_file(tmp_path / "lamp.gltf").materials
    assert mat.roughness == pytest.approx(0.2) and mat.metallic == pytest.approx(0.5)
    assert mat.emissive == pytest.approx((2.0, 0.0, 0.0))  # 1 x half red (linear 1 and 0) x 4
    # the factors alone where there is no texture, nor a strength
    doc["materials"] = [{"name": "plain", "pbrMetallicRoughness": {"metallicFactor": 0.25, "roughnessFactor": 0.5},
                         "emissiveFactor": [0.5, 0.25, 0.0]}]
    (tmp_path / "plain.gltf").write_text(json.dumps(doc))
    (mat,) = scenes.load_mesh_file(tmp_path / "plain.gltf").materials
    assert (mat.roughness, mat.metallic, *mat.emissive) == pytest.approx((0.5, 0.25, 0.5, 0.25, 0.0))
    # an unnamed material's strength cannot be told from trimesh's materials: said, not applied
    doc["materials"] = [{"emissiveFactor": [0.5, 0.25, 0.0],
                         "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}}]
    (tmp_path / "unnamed.gltf").write_text(json.dumps(doc))
    with caplog.at_level("WARNING", logger="rtp"):
        (mat,) = scenes.load_mesh_file(tmp_path / "unnamed.gltf").materials
    assert mat.emissive == pytest.approx((0.5, 0.25, 0.0))
    assert "emissive strength (KHR_materials_emissive_strength) of 1 material(s) is not applied" in caplog.text


def _plain_quad() -> dict:
    """:func:`_gltf_quad` untextured (its material the default PBR one)."""
    doc = _gltf_quad("none.png")
    del doc["images"], doc["textures"], doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]
    return doc


def _with_accessor(doc: dict, data: np.ndarray, component: int, kind: str, **extra: Any) -> int:
    """Append ``data`` to ``doc``'s embedded buffer as a new accessor (its index returned)."""
    import base64

    raw = base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1])
    raw += b"\0" * (-len(raw) % 4)
    blob = np.ascontiguousarray(data).tobytes()
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(raw), "byteLength": len(blob)})
    raw += blob
    doc["buffers"][0] = {"byteLength": len(raw),
                         "uri": "data:application/octet-stream;base64," + base64.b64encode(raw).decode()}
    doc["accessors"].append({"bufferView": len(doc["bufferViews"]) - 1, "componentType": component,
                             "count": len(data), "type": kind, **extra})
    return len(doc["accessors"]) - 1


def test_a_gltf_requiring_an_extension_rtp_does_not_read_is_refused_naming_it(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``extensionsRequired`` was not looked at: a Draco-compressed level (DracoPy not installed) loaded with every
    vertex at the origin, after trimesh's warning only; a meshopt-compressed one was "trimesh could not read ...:
    'uri'"; a ``KHR_mesh_quantization`` one loaded its normalized texture coordinates 65535 times too large. Each
    is a SceneFormatError naming the file, the extension and what to do; an extension a file only uses (the glTF
    specification's optional ones: texture transforms, lights) loads without it, with a warning saying what is
    lost."""
    from rtp.capture.scenes import _mesh

    monkeypatch.setattr(_mesh, "_draco_readable", lambda: False, raising=False)  # (DracoPy absent)
    draco = _plain_quad()
    draco["extensionsUsed"] = draco["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    draco["meshes"][0]["primitives"][0]["extensions"] = {
        "KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0, "TEXCOORD_0": 1}}}
    for accessor in draco["accessors"]:
        del accessor["bufferView"]
    meshopt = _plain_quad()
    meshopt["extensionsUsed"] = meshopt["extensionsRequired"] = ["EXT_meshopt_compression"]
    meshopt["buffers"].append({"byteLength": 92, "extensions": {"EXT_meshopt_compression": {"fallback": True}}})
    for view in meshopt["bufferViews"]:
        view["extensions"] = {"EXT_meshopt_compression": {"buffer": 0, "byteOffset": view["byteOffset"],
                                                          "byteLength": view["byteLength"], "byteStride": 4,
                                                          "mode": "ATTRIBUTES", "count": 1}}
        view["buffer"] = 1
    quantized = _plain_quad()
    quantized["extensionsUsed"] = quantized["extensionsRequired"] = ["KHR_mesh_quantization"]
    uv = _with_accessor(quantized, np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.uint16) * 65535, 5123, "VEC2")
    quantized["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = uv
    custom = _plain_quad()
    custom["extensionsUsed"] = custom["extensionsRequired"] = ["VENDOR_magic"]
    for name, doc, message in (
            ("draco", draco, "KHR_draco_mesh_compression, which rtp does not read (its Draco-compressed geometry "
                             "is not decompressed): install DracoPy"),
            ("meshopt", meshopt, "EXT_meshopt_compression, which rtp does not read (its meshopt-compressed buffers "
                                 "are not decompressed): export it without meshopt compression, or decompress it"),
            ("quantized", quantized, "KHR_mesh_quantization, which rtp does not read (its quantized (integer) "
                                     "positions and texture coordinates are not dequantized): export it without"),
            ("custom", custom, "VENDOR_magic, which rtp does not read: export it without it")):
        (tmp_path / f"{name}.gltf").write_text(json.dumps(doc))
        with pytest.raises(SceneFormatError, match=re.escape(f"{tmp_path / name}.gltf: it requires the glTF "
                                                             f"extension {message}")):
            scenes.load_mesh_file(tmp_path / f"{name}.gltf")
    # used, not required: loaded without it, said
    optional = _plain_quad()
    optional["extensionsUsed"] = ["KHR_texture_transform", "KHR_lights_punctual", "KHR_materials_emissive_strength"]
    (tmp_path / "optional.gltf").write_text(json.dumps(optional))
    with caplog.at_level("WARNING", logger="rtp"):
        scene = scenes.load_mesh_file(tmp_path / "optional.gltf")
    assert scene.meshes[0].positions.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]
    assert [r.getMessage() for r in caplog.records if "extension" in r.getMessage()] == [
        f"{tmp_path / 'optional.gltf'}: it uses glTF extension(s) rtp does not read, loaded without them: "
        "KHR_texture_transform (texture offsets, scales and rotations are not applied); KHR_lights_punctual (its "
        "lights are ignored (the scene keeps the default sun))"]


def test_gltf_accessors_and_primitives_trimesh_misreads_are_refused_naming_them(tmp_path: Path) -> None:
    """trimesh reads a sparse accessor's base values only (zeros without a buffer view), reads normalized integers
    as the integers (texture coordinates 65535 times too large: core glTF allows them without an extension) and
    drops triangle fans without a word (a level of fans "contained no triangles"). Each is a SceneFormatError
    naming the file, mesh, primitive and accessor; a triangle strip loads, converted to triangles."""
    sparse = _plain_quad()
    indices = _with_accessor(sparse, np.array([2], np.uint32), 5125, "SCALAR")
    values = _with_accessor(sparse, np.array([[5, 5, 5]], np.float32), 5126, "VEC3")
    sparse["accessors"][0]["sparse"] = {
        "count": 1, "indices": {"bufferView": sparse["accessors"][indices]["bufferView"], "componentType": 5125},
        "values": {"bufferView": sparse["accessors"][values]["bufferView"]}}
    normalized = _plain_quad()
    uv = _with_accessor(normalized, np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.uint16) * 65535, 5123, "VEC2",
                        normalized=True)
    normalized["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = uv
    fan = _plain_quad()
    fan["meshes"][0]["primitives"][0]["mode"] = 6
    fan["meshes"][0]["primitives"][0]["indices"] = _with_accessor(fan, np.array([0, 1, 2, 3], np.uint16), 5123,
                                                                  "SCALAR")
    for name, doc, message in (
            ("sparse", sparse, "mesh 0 primitive 0: its POSITION is a sparse accessor (accessor 0), which rtp does "
                               "not read"),
            ("normalized", normalized, f"mesh 0 primitive 0: its TEXCOORD_0 is quantized (normalized integers, "
                                       f"accessor {uv}), which rtp does not dequantize"),
            ("fan", fan, "mesh 0 primitive 0 is a triangle fan (mode 6), which rtp does not read")):
        (tmp_path / f"{name}.gltf").write_text(json.dumps(doc))
        with pytest.raises(SceneFormatError, match=re.escape(f"{tmp_path / name}.gltf: {message}")):
            scenes.load_mesh_file(tmp_path / f"{name}.gltf")
    strip = _plain_quad()
    strip["meshes"][0]["primitives"][0]["mode"] = 5
    strip["meshes"][0]["primitives"][0]["indices"] = _with_accessor(strip, np.array([0, 1, 3, 2], np.uint16), 5123,
                                                                    "SCALAR")
    (tmp_path / "strip.gltf").write_text(json.dumps(strip))
    (mesh,) = scenes.load_mesh_file(tmp_path / "strip.gltf").meshes
    pos = mesh.positions.astype(np.float64)[mesh.indices.astype(np.int64)]
    normals = np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0])
    assert len(mesh.indices) == 2 and normals[:, 2] == pytest.approx([1.0, 1.0])  # both counter-clockwise, facing +z


def test_gltf_vertex_colours_multiply_the_base_colour(tmp_path: Path) -> None:
    """glTF's ``COLOR_0`` multiplies the material's base colour; trimesh keeps it beside the material, and the
    loader dropped it: a level painted with vertex colours (as many exporters bake lighting or tints) loaded in
    its materials' plain factors. The base colour is now multiplied by the colours' mean, read as float, unsigned
    8-bit or 16-bit normalized, RGB (alpha 1) or RGBA."""
    for name, data, component in (
            ("float", np.tile(np.array([[0.5, 1.0, 0.25, 1.0]], np.float32), (4, 1)), 5126),
            ("unorm8", np.tile(np.array([[255, 255, 51, 0]], np.uint8), (4, 1)), 5121),
            ("unorm16", np.tile(np.array([[65535, 13107, 65535, 32768]], np.uint16), (4, 1)), 5123)):
        doc = _plain_quad()
        doc["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [1.0, 0.2, 1.0, 1.0]
        if name == "unorm8":  # RGB, in a 4-byte aligned buffer view
            acc = _with_accessor(doc, data, component, "VEC3", normalized=True)
            doc["bufferViews"][-1]["byteStride"] = 4
        else:
            acc = _with_accessor(doc, data, component, "VEC4", normalized=component != 5126)
        doc["meshes"][0]["primitives"][0]["attributes"]["COLOR_0"] = acc
        (tmp_path / f"{name}.gltf").write_text(json.dumps(doc))
        (mat,) = scenes.load_mesh_file(tmp_path / f"{name}.gltf").materials
        expected = {"float": (0.5, 0.2, 0.25, 1.0), "unorm8": (1.0, 0.2, 0.2, 1.0),
                    "unorm16": (1.0, 0.04, 1.0, 0.5)}[name]
        assert mat.base_color == pytest.approx(expected, abs=0.003), name


def test_an_objs_material_library_is_found_where_trimesh_finds_it(tmp_path: Path, caplog: pytest.LogCaptureFixture):
    """The loader read an OBJ's ``mtllib`` itself, trimesh by its own rules: a library in ``../materials/``
    (outside the OBJ's folder, which trimesh refuses) gave trimesh's grey placeholder texture, without a
    warning; one named by a path of another machine (``C:\\art\\room.mtl``) that trimesh found by its name
    beside the OBJ was said to be unreadable and its materials replaced by the default. Both read the same
    library now, and a ``map_Kd`` relative to a library in another folder is found there."""
    obj = "mtllib {}\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nusemtl red\nf 1/1 2/2 3/3\n"
    (tmp_path / "models").mkdir()
    (tmp_path / "materials").mkdir()
    PIL.new("RGBA", (4, 4), (0, 0, 255, 255)).save(tmp_path / "materials" / "blue.png")
    (tmp_path / "materials" / "up.mtl").write_text("newmtl red\nKd 1 0 0\nmap_Kd blue.png\n")
    (tmp_path / "models" / "up.obj").write_text(obj.format("../materials/up.mtl"))
    (tmp_path / "models" / "room.mtl").write_text("newmtl red\nKd 0 1 0\n")
    (tmp_path / "models" / "abs.obj").write_text(obj.format("C:\\art\\room.mtl"))
    with caplog.at_level("WARNING", logger="rtp"):
        (up,) = scenes.load_mesh_file(tmp_path / "models" / "up.obj").materials
        (absolute,) = scenes.load_mesh_file(tmp_path / "models" / "abs.obj").materials
    assert not caplog.records
    assert up.name == "red" and up.texture is not None and tuple(up.texture[0, 0]) == (0, 0, 255, 255)
    assert absolute.name == "red" and absolute.texture is None
    assert absolute.base_color == pytest.approx((0.0, 1.0, 0.0, 1.0))


def test_a_mesh_file_with_values_a_scene_cannot_hold_is_a_format_error_naming_it(tmp_path: Path):
    """A glTF triangle indexing a vertex the file does not have was a bare IndexError from numpy (trimesh does
    not check indices with process=False); a NaN vertex or a roughness of 1.5 was the scene model's
    ParameterError ("Material.roughness: ..."), naming neither the file nor the geometry. Each is a
    SceneFormatError naming both now."""
    import base64

    gltf = _gltf_quad("none.png")
    del gltf["images"], gltf["textures"], gltf["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]
    raw = base64.b64decode(gltf["buffers"][0]["uri"].split(",", 1)[1])
    bad = raw[:80] + np.array([0, 1, 2, 0, 2, 7], np.uint16).tobytes()
    gltf["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(bad).decode()
    (tmp_path / "index.gltf").write_text(json.dumps(gltf))
    gltf["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(raw).decode()
    gltf["materials"][0]["pbrMetallicRoughness"]["roughnessFactor"] = 1.5
    (tmp_path / "rough.gltf").write_text(json.dumps(gltf))
    (tmp_path / "nan.obj").write_text("v nan 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n")
    for name, message in (("index.gltf", r"its triangles index vertices in \[0, 7\], expected \[0, 4\)"),
                          ("rough.gltf", r"its material: Material.roughness: expected a finite number"),
                          ("nan.obj", r"Mesh.positions: expected finite values")):
        with pytest.raises(SceneFormatError, match=rf"{re.escape(str(tmp_path / name))}: geometry '[^']+': {message}"):
            scenes.load_mesh_file(tmp_path / name)


def test_a_mesh_file_far_from_the_origin_loads_with_a_warning(tmp_path: Path, caplog: pytest.LogCaptureFixture):
    """float32, what the renderers draw with, resolves 6 cm at 1e6 m: a room there captured with 66 % unseen
    pixels (10 % at the origin), without a word. It loads with a warning naming the distance and the
    resolution; a room 1e5 m away (8 mm steps) loads without one."""
    for offset, warned in ((1e6, True), (1e5, False)):
        (tmp_path / "far.obj").write_text("".join(f"v {x + offset} 0 {z}\n" for x, z in ((0, 0), (1, 0), (1, 1)))
                                          + "f 1 3 2\n")
        caplog.clear()
        with caplog.at_level("WARNING", logger="rtp"):
            scenes.load_mesh_file(tmp_path / "far.obj")
        said = [r.getMessage() for r in caplog.records if "from the origin" in r.getMessage()]  # (a 1 m level: units)
        if warned:
            assert len(said) == 1 and "far.obj: its geometry lies up to 1000001 m from the origin" in said[0]
            assert "resolves only 0.062 m" in said[0]
        else:
            assert not said


#: A unit quad in the z = 0 plane facing +z, with texture coordinates and a material named, and no ``mtllib``.
QUAD_OBJ = ("{}v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n{}"
            "f 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")


def test_an_obj_without_a_material_library_is_untextured_as_one_whose_library_cannot_be_read(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
):
    """An OBJ with texture coordinates and no ``mtllib`` line got trimesh's grey 2x2 placeholder texture (values
    100 of 255, a white base colour: an albedo of 0.39 rather than the default 0.8) and its placeholder's
    roughness, unlike one whose library cannot be read: both are the untextured default material now (no
    warning for the OBJ without one: it names no library to lose)."""
    import dataclasses

    from rtp.scene import Material

    (tmp_path / "lost.obj").write_text(QUAD_OBJ.format("mtllib absent.mtl\n", "usemtl red\n"))
    with caplog.at_level("WARNING", logger="rtp"):
        (lost,) = scenes.load_mesh_file(tmp_path / "lost.obj").materials
    assert any("absent.mtl cannot be read" in r.getMessage() for r in caplog.records)
    for head, use in (("", "usemtl red\n"), ("", ""), ("# no library\n", "")):
        (tmp_path / "nolib.obj").write_text(QUAD_OBJ.format(head, use))
        caplog.clear()
        with caplog.at_level("WARNING", logger="rtp"):
            (mat,) = scenes.load_mesh_file(tmp_path / "nolib.obj").materials
        assert mat.texture is None, "trimesh's placeholder texture"
        assert dataclasses.replace(mat, name="") == dataclasses.replace(lost, name="") == Material(name="")
        assert not caplog.records


@pytest.mark.gl
def test_an_obj_without_a_material_library_renders_the_default_albedo(tmp_path: Path) -> None:
    """The untextured default material of an OBJ without ``mtllib`` is a plain albedo of its base colour (0.8,
    sRGB-encoded), as an OBJ whose library cannot be read gives (trimesh's placeholder gave 100 / 255)."""
    from rtp.plugins.moderngl import Renderer
    from rtp.scene import Camera

    albedo = {}
    for name, head in (("nolib", ""), ("lost", "mtllib absent.mtl\n")):
        (tmp_path / f"{name}.obj").write_text(QUAD_OBJ.format(head, ""))
        scene = scenes.load_mesh_file(tmp_path / f"{name}.obj")
        with Renderer(32, 32) as r:
            r.load_scene(scene)
            frame = r.render(Camera((0.5, 0.5, 1.5)))
        albedo[name] = frame.albedo[8:24, 8:24]
        np.testing.assert_allclose(albedo[name], 0.8, atol=1 / 255)
    np.testing.assert_array_equal(albedo["nolib"], albedo["lost"])


# -- fetching: apt-get and dpkg-deb replaced by a local fake ------------------------------------------

SPLITS = "train: [m1, m2]\nvalidation: []\ntest: [m3]\n"
OA = "usr/share/games/openarena/baseoa"


def _pk3_bytes(files: dict[str, bytes | str]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)
    return buf.getvalue()


def _packages() -> dict[str, dict[str, bytes]]:
    """The files of fake Debian packages: map m1 in an OpenArena archive whose textures and shaders
    are in another archive of the group, map m2 gzipped as libirrlicht-doc ships its level."""
    return {
        "openarena-081-maps": {f"{OA}/map-m1.pk3": _pk3_bytes({"maps/m1.bsp": write_test_bsp()})},
        "openarena-081-textures": {f"{OA}/pak-tex.pk3": _pk3_bytes({
            "textures/test/wall.jpg": _jpg((200, 30, 30)), "textures/test/other.png": _png((20, 40, 220)),
            "scripts/test.shader": SHADER})},
        "openarena-oacmp1": {},
        "libirrlicht-doc": {"usr/share/doc/irrlicht/media/map-m2.pk3.gz": gzip.compress(
            _pk3_bytes({"maps/m2.bsp": write_test_bsp()}))},
    }


def _deb_bytes(files: dict[str, bytes]) -> bytes:
    """A Debian package as ``ar`` lays it out (``debian-binary``, ``control.tar.xz``, ``data.tar.xz``), its data
    member a zip of ``files`` here (what the fake ``dpkg-deb -x`` of :func:`_fake_apt` unpacks)."""
    out = b"!<arch>\n"
    for name, data in (("debian-binary", b"2.0\n"), ("control.tar.xz", b"control"), ("data.tar.xz", _pk3_bytes(files))):
        out += f"{name:<16}{0:<12}{0:<6}{0:<6}{100644:<8}{len(data):<10}`\n".encode() + data + b"\n" * (len(data) % 2)
    return out


def _deb_data(path: str | Path) -> bytes:
    """The ``data.tar.xz`` member of a package of :func:`_deb_bytes`."""
    raw, pos = Path(path).read_bytes(), 8
    while pos < len(raw):
        head, n = raw[pos:pos + 60], int(raw[pos + 48:pos + 58])
        if head[:16].strip() == b"data.tar.xz":
            return raw[pos + 60:pos + 60 + n]
        pos += 60 + n + n % 2
    raise zipfile.BadZipFile(f"{path}: no data member")


def _fake_apt(monkeypatch: pytest.MonkeyPatch, packages: dict[str, dict[str, bytes]]) -> list[list[str]]:
    """Replace ``_fetch._run``, the one function that runs ``apt-get download`` (the network) and
    ``dpkg-deb -x``: the fake writes ``<package>_1.0_all.deb`` (an ``ar`` archive as a real one, its data a zip of
    the package's files here) and unpacks it. Returns the commands run."""
    calls: list[list[str]] = []

    def run(cmd, cwd: Path, debs: Path | None = None) -> None:
        calls.append(list(cmd))
        if list(cmd[:2]) == ["apt-get", "download"]:
            for pkg in cmd[2:]:
                (cwd / f"{pkg}_1.0_all.deb").write_bytes(_deb_bytes(packages[pkg]))
        else:
            assert list(cmd[:2]) == ["dpkg-deb", "-x"], cmd
            with zipfile.ZipFile(io.BytesIO(_deb_data(cmd[2]))) as z:
                z.extractall(cmd[3])

    monkeypatch.setattr(scenes._fetch, "_run", run)
    return calls


def test_fetch_downloads_unpacks_once_and_indexes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """fetch: downloads only the packages not in ``debs/``, unpacks each package once, gunzips
    ``*.pk3.gz``, indexes the maps (paths relative to the cache) with the OpenArena archives as one
    texture group, converts with ``convert=True``, and works without tqdm; a listed map the
    packages lack is FetchError."""
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    calls = _fake_apt(monkeypatch, _packages())
    out = scenes.fetch(cache, ["m1", "m2"], splits=splits, convert=True)
    n = len(scenes.PACKAGES)
    assert calls[:n] == [["apt-get", "download", p] for p in scenes.PACKAGES]  # one at a time, each kept as it arrives
    assert sorted(c[2].rsplit("/", 1)[-1] for c in calls[n:]) == sorted(f"{p}_1.0_all.deb" for p in scenes.PACKAGES)
    index = json.loads((cache / "index.json").read_text())
    m1, tex, m2 = f"root/{OA}/map-m1.pk3", f"root/{OA}/pak-tex.pk3", "pk3/map-m2.pk3"
    assert index["maps"] == {"m1": m1, "m2": m2}
    assert index["groups"] == {"openarena": [m1, tex], "map-m2": [m2]}
    assert out == {"m1": cache / m1, "m2": cache / m2}
    assert sorted(p.name for p in (cache / "converted").iterdir()) == [f"m1.v{CACHE_VERSION}.npz", f"m2.v{CACHE_VERSION}.npz"]
    wall = scene_by_name("m1", cache, splits=splits).materials[0]
    assert wall.texture is not None and wall.texture[0, 0, 0] > 150  # from the group's texture archive
    assert scene_by_name("m2", cache, splits=splits).materials[0].texture is None  # a stand-alone archive
    assert scenes.scene_list(cache, splits) == [
        {"name": "m1", "split": "train", "fetched": True, "converted": True},
        {"name": "m2", "split": "train", "fetched": True, "converted": True},
        {"name": "m3", "split": "test", "fetched": False, "converted": False}]
    calls.clear()
    assert scenes.fetch(cache, ["m1"], splits=splits, progress=False) == {"m1": cache / m1}
    assert calls == []  # nothing downloaded or unpacked again
    with pytest.raises(scenes.FetchError, match=r"not found in the packages .*: \['m3'\]"):
        scenes.fetch(cache, ["m1", "m3"], splits=splits, progress=False)


@pytest.mark.parametrize(("package", "files", "message"), [
    ("libirrlicht-doc", {"usr/share/doc/irrlicht/media/map-m2.pk3.gz": b"\x1f\x8b\x08 cut short"},
     r"could not gunzip .*map-m2.pk3.gz"),
    ("libirrlicht-doc", {"usr/share/doc/irrlicht/media/map-m2.pk3.gz": b"not gzip"}, r"could not gunzip .*map-m2.pk3.gz"),
    ("openarena-081-maps", {f"{OA}/map-m1.pk3": b"not a zip"}, r"map-m1.pk3 is not a pk3 \(zip\) archive"),
])
def test_fetch_damaged_archives_raise_fetch_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, package: str,
                                                  files: dict[str, bytes], message: str):
    """A damaged archive in the packages is FetchError naming it (not gzip.BadGzipFile, EOFError or
    zipfile.BadZipFile), and leaves no half-written archive behind."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    _fake_apt(monkeypatch, _packages() | {package: files})
    with pytest.raises(scenes.FetchError, match=message):
        scenes.fetch(tmp_path / "cache", ["m1"], splits=splits, progress=False)
    assert not list((tmp_path / "cache" / "pk3").glob("*.tmp"))


def test_a_failed_download_leaves_no_package_cut_short_and_a_damaged_one_is_fetched_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    """apt-get download on a full disk (or a dropped connection) left its .deb files cut short in
    ``debs/``, which every later fetch took for packages: dpkg-deb failed on them until the user
    deleted the cache by hand. The download now goes to a folder of its own, moved into ``debs/``
    only once it succeeded; a damaged package already there (an older rtp's) is removed when
    dpkg-deb fails on it, so the next fetch downloads it again."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    packages = _packages()
    calls = _fake_apt(monkeypatch, packages)
    working = scenes._fetch._run

    def full_disk(cmd, cwd: Path, debs: Path | None = None) -> None:  # noqa: ANN001
        if list(cmd[:2]) == ["apt-get", "download"]:
            (cwd / f"{cmd[2]}_1.0_all.deb").write_bytes(_pk3_bytes(packages[cmd[2]])[:100])  # cut short
            raise scenes.FetchError("apt-get download ... failed with exit code 100: ... (28: No space left on device)")
        working(cmd, cwd)

    monkeypatch.setattr(scenes._fetch, "_run", full_disk)
    with pytest.raises(scenes.FetchError, match="No space left on device"):
        scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    assert list((cache / "debs").iterdir()) == []  # no package, no download folder
    monkeypatch.setattr(scenes._fetch, "_run", working)
    assert scenes.fetch(cache, ["m1"], splits=splits, progress=False) == {"m1": cache / "root" / OA / "map-m1.pk3"}
    # a package cut short by an older rtp: dpkg-deb fails on it, it is removed, the next fetch takes it again
    cut = cache / "debs" / "openarena-081-textures_1.0_all.deb"
    cut.write_bytes(cut.read_bytes()[:100])
    (cache / "root" / ".unpacked").write_text("")

    def dpkg_fails_on_cut(cmd, cwd: Path, debs: Path | None = None) -> None:  # noqa: ANN001
        if list(cmd[:2]) == ["dpkg-deb", "-x"] and Path(cmd[2]).stat().st_size == 100:
            raise scenes.FetchError(f"dpkg-deb -x {cmd[2]} {cmd[3]} failed with exit code 2: tar: Unexpected EOF in archive")
        working(cmd, cwd)

    monkeypatch.setattr(scenes._fetch, "_run", dpkg_fails_on_cut)
    with pytest.raises(scenes.FetchError, match=r"Unexpected EOF in archive \(removed openarena-081-textures_1\.0_all\.deb: "
                                                r"the next `rtp scenes fetch` downloads it again\)$"):
        scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    assert not cut.exists()
    calls.clear()
    assert scenes.fetch(cache, ["m1"], splits=splits, progress=False) == {"m1": cache / "root" / OA / "map-m1.pk3"}
    assert calls[0] == ["apt-get", "download", "openarena-081-textures"] and cut.stat().st_size > 100


def test_run_turns_command_failures_into_fetch_errors(tmp_path: Path):
    """apt-get/dpkg-deb failures are FetchError: a missing program (saying what to do instead), a
    command that cannot start, a non-zero exit (with the last 5 lines of its stderr)."""
    from rtp.capture.scenes._fetch import _run

    with pytest.raises(scenes.FetchError, match=r"rtp-no-such-tool not found: fetching needs a Debian/Ubuntu system"):
        _run(["rtp-no-such-tool", "download"], tmp_path)
    with pytest.raises(scenes.FetchError, match="could not run"):
        _run([sys.executable, "-c", "pass"], tmp_path / "no-such-folder")
    script = "import sys; sys.stderr.write(''.join(f'line {i}\\n' for i in range(7))); sys.exit(3)"
    with pytest.raises(scenes.FetchError, match=r"failed with exit code 3: line 2 \| line 3 \| line 4 \| line 5 \| line 6$"):
        _run([sys.executable, "-c", script], tmp_path)
    _run([sys.executable, "-c", "pass"], tmp_path)  # success: no error


def test_a_full_disk_while_unpacking_keeps_the_whole_package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """dpkg-deb failing on a whole package (the disk full while unpacking) removed the package as if it were
    damaged: the next fetch downloaded the 94 MB again (or could not, offline). A whole package is kept, the error
    says to free space and fetch again, and that fetch unpacks it without downloading; one cut short is still
    removed (test above)."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    calls = _fake_apt(monkeypatch, _packages())
    working = scenes._fetch._run

    def full_disk(cmd, cwd: Path, debs: Path | None = None) -> None:  # noqa: ANN001
        if list(cmd[:2]) == ["dpkg-deb", "-x"] and "textures" in cmd[2]:
            working(cmd, cwd)  # (part of it written)
            raise scenes.FetchError(f"dpkg-deb -x {cmd[2]} {cmd[3]} failed with exit code 2: tar: ./usr/share/games/"
                                    "openarena/baseoa/pak-tex.pk3: Cannot write: No space left on device")
        working(cmd, cwd)

    monkeypatch.setattr(scenes._fetch, "_run", full_disk)
    deb = cache / "debs" / "openarena-081-textures_1.0_all.deb"
    with pytest.raises(scenes.FetchError, match=rf"No space left on device \(kept {re.escape(str(deb))}, a whole "
                                                r"package: .*free some space and run `rtp scenes fetch` again"):
        scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    assert deb.is_file() and not (cache / "index.json").exists()
    assert "openarena-081-textures_1.0_all.deb" not in (cache / "root" / ".unpacked").read_text()
    monkeypatch.setattr(scenes._fetch, "_run", working)
    calls.clear()
    assert scenes.fetch(cache, ["m1"], splits=splits, progress=False) == {"m1": cache / "root" / OA / "map-m1.pk3"}
    assert calls == [["dpkg-deb", "-x", str(d), str(cache / "root")] for d in  # unpacked again, nothing downloaded
                     (deb, cache / "debs" / "openarena-oacmp1_1.0_all.deb")]  # (and the one after it, not yet)
    assert scene_by_name("m1", cache, splits=splits).materials[0].texture is not None


def test_a_fetch_that_unpacks_again_and_stops_leaves_no_index_of_the_earlier_one(tmp_path: Path,
                                                                                 monkeypatch: pytest.MonkeyPatch):
    """A fetch that unpacked the packages again (after a damaged archive, as its error says: delete ``root/.unpacked``
    and ``pk3/``) and was interrupted (Ctrl-C, kill -9) or failed midway left the earlier fetch's ``index.json``:
    `rtp scenes list` counted every map as fetched while their archives were cut short or gone, and loading one
    failed on its archive ("BSP source not found: .../pk3/map-20kdm2.pk3"). The index is removed before the
    archives change, so the cache reads as not fetched until a fetch ends; the next fetch writes it again."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    _fake_apt(monkeypatch, _packages())
    working = scenes._fetch._run
    scenes.fetch(cache, ["m1", "m2"], splits=splits, progress=False)
    assert [r["fetched"] for r in scenes.scene_list(cache, splits)] == [True, True, False]

    def interrupted(cmd, cwd: Path, debs: Path | None = None) -> None:  # noqa: ANN001
        if list(cmd[:2]) == ["dpkg-deb", "-x"] and "maps" in cmd[2]:
            (cache / "root" / OA / "map-m1.pk3").write_bytes(b"PK\x03\x04 cut")  # tar had written part of it
            raise KeyboardInterrupt
        working(cmd, cwd)

    (cache / "root" / ".unpacked").unlink()
    shutil.rmtree(cache / "pk3")
    monkeypatch.setattr(scenes._fetch, "_run", interrupted)
    with pytest.raises(KeyboardInterrupt):
        scenes.fetch(cache, ["m1", "m2"], splits=splits, progress=False)
    assert not (cache / "index.json").exists()
    assert [r["fetched"] for r in scenes.scene_list(cache, splits)] == [False, False, False]
    with pytest.raises(scenes.SceneNotFoundError, match="run `rtp scenes fetch --cache-dir"):
        scenes.check_map("m2", cache, splits=splits)
    monkeypatch.setattr(scenes._fetch, "_run", working)
    scenes.fetch(cache, ["m1", "m2"], splits=splits, progress=False)
    assert [r["fetched"] for r in scenes.scene_list(cache, splits)] == [True, True, False]
    # the gunzipped archive alone deleted (the packages unpacked): its gunzip interrupted leaves no index either

    def no_gunzip(src, dst, *args) -> None:  # noqa: ANN001
        raise KeyboardInterrupt

    shutil.rmtree(cache / "pk3")
    monkeypatch.setattr(scenes._fetch.shutil, "copyfileobj", no_gunzip)
    with pytest.raises(KeyboardInterrupt):
        scenes.fetch(cache, ["m1", "m2"], splits=splits, progress=False)
    assert not (cache / "index.json").exists()
    monkeypatch.undo()
    _fake_apt(monkeypatch, _packages())
    scenes.fetch(cache, ["m1", "m2"], splits=splits, progress=False)
    assert scene_by_name("m2", cache, splits=splits).name == "m2"


def test_a_fetch_into_a_cache_it_cannot_write_is_a_fetch_error_or_the_maps_fetched_there(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture):
    """A fetch into a read-only scene cache (a shared one, which docs/scaling.md suggests) failed with the system's
    bare OSError "Read-only file system: '.../.rtp-writer.lock'", even where the cache held every map asked for.
    Those maps are now returned as fetched there, with a warning (and converted with ``convert=True``); a map the
    cache lacks is a FetchError saying the folder cannot be written and what to
    do, before anything is downloaded."""
    import contextlib
    import errno

    import rtp.sdk.files

    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    calls = _fake_apt(monkeypatch, _packages())
    scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    calls.clear()

    @contextlib.contextmanager
    def read_only(folder, job, busy, **kw):  # noqa: ANN001, ANN003
        raise OSError(errno.EROFS, "Read-only file system", str(Path(folder) / ".rtp-writer.lock"))
        yield

    monkeypatch.setattr(rtp.sdk.files, "writer_lock", read_only)
    with caplog.at_level(logging.WARNING, logger="rtp.capture"):
        assert scenes.fetch(cache, ["m1"], splits=splits, progress=False, convert=True) == {
            "m1": cache / "root" / OA / "map-m1.pk3"}
    assert "cannot be written (Read-only file system: " in caplog.text and calls == []
    assert (cache / "converted" / f"m1.v{CACHE_VERSION}.npz").is_file()
    with pytest.raises(scenes.FetchError, match=rf"cannot write to the scene cache {re.escape(str(cache.resolve()))} "
                                                r"\(Read-only file system: .*\.rtp-writer\.lock\): fetch into a folder "
                                                r"you can write"):
        scenes.fetch(cache, ["m1", "m3"], splits=splits, progress=False)
    with pytest.raises(scenes.FetchError, match="cannot write to the scene cache"):
        scenes.fetch(tmp_path / "empty", ["m1"], splits=splits, progress=False)
    assert calls == []


def test_a_fetch_after_the_packages_were_deleted_downloads_none_that_is_unpacked(tmp_path: Path,
                                                                                 monkeypatch: pytest.MonkeyPatch):
    """The packages in ``debs/`` (169 MB) are only the source of ``root/``: with them deleted after a fetch, every
    later fetch downloaded the four again (or failed offline) for archives it had. A package that ``root/.unpacked``
    records is not downloaded again; with that record deleted too (as a damaged archive's error says), it is."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    calls = _fake_apt(monkeypatch, _packages())
    scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    shutil.rmtree(cache / "debs")
    calls.clear()
    assert scenes.fetch(cache, ["m1", "m2"], splits=splits, progress=False) == {
        "m1": cache / "root" / OA / "map-m1.pk3", "m2": cache / "pk3" / "map-m2.pk3"}
    assert calls == []
    (cache / "root" / ".unpacked").unlink()
    scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    assert [c for c in calls if c[0] == "apt-get"] == [["apt-get", "download", p] for p in scenes.PACKAGES]


def _fake_apt_get(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, stderr: str) -> None:
    """An ``apt-get`` first on PATH that prints ``stderr`` and fails as apt does (exit code 100)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    tool = bin_dir / "apt-get"
    tool.write_text(f"#!{sys.executable}\nimport sys\nsys.stdout.write('Err:1 http://deb.debian.org/debian x\\n')\n"
                    f"sys.stderr.write({stderr!r})\nsys.exit(100)\n")
    tool.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}:{__import__('os').environ['PATH']}")


@pytest.mark.parametrize(("stderr", "why"), [
    ("W: Download is performed unsandboxed as root as file '/c/libirrlicht-doc_1.8.5_all.deb' couldn't be accessed "
     "by user '_apt'. - pkgAcquire::Run (13: Permission denied)\n"
     "E: Failed to fetch http://deb.debian.org/debian/pool/main/o/x.deb  Could not resolve 'deb.debian.org'\n"
     "W: Some index files failed to download.\n",
     r"E: Failed to fetch http://deb\.debian\.org/\S+  Could not resolve 'deb\.debian\.org' \(no network, or no mirror "
     r"reachable\? check the connection"),
    ("E: Unable to locate package openarena-081-maps\n",
     r"E: Unable to locate package openarena-081-maps \(the system's package lists do not know them: run `sudo "
     r"apt-get update`"),
    ("E: Failed to fetch http://deb.debian.org/debian/pool/main/o/openarena-maps/openarena-081-maps_0.8.5split-14_all.deb"
     "  404  Not Found [IP: 151.101.2.132 80]\n",
     r"E: Failed to fetch http://deb\.debian\.org/\S+  404  Not Found \[IP: [\d.]+ 80\] \(the mirror does not have the "
     r"version the system's package lists name, .*: run `sudo apt-get update`, then fetch again;"),
    ("E: Failed to fetch http://deb.debian.org/debian/pool/main/o/x.deb  File has unexpected size (5120 != 40249856). "
     "Mirror sync in progress? [IP: 151.101.2.132 80]\n",
     r"E: Failed to fetch .*unexpected size .* \(the mirror does not have the version .*: run `sudo apt-get update`"),
], ids=["offline", "no-lists", "404", "html-page"])
def test_a_download_that_fails_offline_says_why_in_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            stderr: str, why: str):
    """apt-get download with no network (or no package lists) failed with its last lines, apt's warnings among them
    ("W: Download is performed unsandboxed as root ..." hid the cause) and no word of what to do. The error is one
    line of apt's errors, the likely cause and where to put the packages by hand; nothing is left in ``debs/``."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    _fake_apt_get(tmp_path, monkeypatch, stderr)
    with pytest.raises(scenes.FetchError) as err:
        scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    text = str(err.value)
    assert "\n" not in text and "W: " not in text, text
    assert re.search(rf"^apt-get download {scenes.PACKAGES[0]} failed with exit code 100: {why}", text), text
    assert text.endswith(f"`apt-get download {' '.join(scenes.PACKAGES)}`, into {cache / 'debs'} and run `rtp scenes "
                         "fetch` again)")
    assert list((cache / "debs").iterdir()) == []


def test_an_interrupted_download_keeps_the_packages_that_arrived_and_the_next_fetch_downloads_the_rest(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    """One ``apt-get download`` of all four packages (177 MB) that failed or was interrupted (Ctrl-C, a dropped
    connection) near its end kept nothing: the next fetch downloaded everything again, and on a flaky network
    never got through. Packages are downloaded one at a time and each is kept as it arrives: the error says what
    was kept and which packages remain, and the next fetch downloads only those."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    calls = _fake_apt(monkeypatch, _packages())
    working = scenes._fetch._run
    third = scenes.PACKAGES[2]

    def drops(cmd, cwd: Path, debs: Path | None = None) -> None:  # noqa: ANN001
        if list(cmd) == ["apt-get", "download", third]:
            (cwd / f"{third}_1.0_all.deb").write_bytes(b"!<arch>\ncut")  # half of it, then the network went
            raise scenes.FetchError(f"apt-get download {third} failed with exit code 100: E: Failed to fetch "
                                    "http://deb.debian.org/x.deb  Connection timed out")
        working(cmd, cwd)

    monkeypatch.setattr(scenes._fetch, "_run", drops)
    rest = " ".join(scenes.PACKAGES[2:])
    with pytest.raises(scenes.FetchError, match=rf"Connection timed out \(no network, .*; kept the 2 packages downloaded "
                                                rf"before it; or put .*`apt-get download {rest}`, into"):
        scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    assert sorted(p.name for p in (cache / "debs").iterdir()) == sorted(f"{p}_1.0_all.deb" for p in scenes.PACKAGES[:2])

    def interrupted(cmd, cwd: Path, debs: Path | None = None) -> None:  # noqa: ANN001
        if list(cmd) == ["apt-get", "download", third]:
            working(cmd, cwd)
            return
        if list(cmd[:2]) == ["apt-get", "download"]:
            raise KeyboardInterrupt  # Ctrl-C during the fourth
        working(cmd, cwd)

    calls.clear()
    monkeypatch.setattr(scenes._fetch, "_run", interrupted)
    with pytest.raises(KeyboardInterrupt):
        scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    assert sorted(p.name for p in (cache / "debs").iterdir()) == sorted(f"{p}_1.0_all.deb" for p in scenes.PACKAGES[:3])
    monkeypatch.setattr(scenes._fetch, "_run", working)
    calls.clear()
    assert scenes.fetch(cache, ["m1"], splits=splits, progress=False) == {"m1": cache / "root" / OA / "map-m1.pk3"}
    assert [c for c in calls if c[0] == "apt-get"] == [["apt-get", "download", scenes.PACKAGES[3]]]


def test_a_download_folder_left_by_a_killed_fetch_is_removed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A fetch killed outright while downloading (kill -9, SIGTERM, a closed terminal: no cleanup runs) left its
    ``debs/.download-*`` folder, with up to 177 MB of packages cut short in it, for good: every later fetch made a
    new one beside it. The next fetch, which holds the cache's lock, removes it."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    stale = cache / "debs" / ".download-k2j4x9ab"
    stale.mkdir(parents=True)
    (stale / "openarena-081-textures_1.0_all.deb").write_bytes(b"!<arch>\n" + b"x" * 1000)
    _fake_apt(monkeypatch, _packages())
    assert scenes.fetch(cache, ["m1"], splits=splits, progress=False) == {"m1": cache / "root" / OA / "map-m1.pk3"}
    assert sorted(p.name for p in (cache / "debs").iterdir()) == sorted(f"{p}_1.0_all.deb" for p in scenes.PACKAGES)


def test_a_command_output_that_is_not_text_is_still_its_failure(tmp_path: Path):
    """Bytes the command's output cannot decode (a file name of another encoding in dpkg-deb's error) raised
    UnicodeDecodeError from _run, not the FetchError of the command's failure."""
    from rtp.capture.scenes._fetch import _run

    script = "import sys; sys.stderr.buffer.write(b'tar: caf\\xe9.pk3: Cannot open\\n'); sys.exit(2)"
    with pytest.raises(scenes.FetchError, match=r"failed with exit code 2: tar: caf.\.pk3: Cannot open$"):
        _run([sys.executable, "-c", script], tmp_path)


def test_a_second_fetch_into_the_same_cache_is_refused_while_one_runs(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch):
    """Two fetches into one cache at once both downloaded and unpacked into the same folders (and gunzipped into the
    same temporary file, renamed away under the other). A second fetch is refused at once, naming the one running,
    before it downloads or writes anything; once that one ends a fetch runs."""
    from rtp.sdk.files import writer_lock

    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    cache.mkdir()
    calls = _fake_apt(monkeypatch, _packages())
    with writer_lock(cache, "rtp scenes fetch", RuntimeError):  # (another process's, as far as flock goes)
        with pytest.raises(scenes.FetchError, match=rf"another fetch into {re.escape(str(cache.resolve()))} is running "
                                                    rf"\(rtp scenes fetch, pid \d+\): wait for it to end"):
            scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    assert calls == [] and not (cache / "debs").exists()
    assert scenes.fetch(cache, ["m1"], splits=splits, progress=False) == {"m1": cache / "root" / OA / "map-m1.pk3"}


def test_an_empty_scene_cache_variable_is_unset(monkeypatch: pytest.MonkeyPatch):
    """``RTP_SCENE_CACHE=`` (set, but empty) made the current folder the scene cache."""
    monkeypatch.setenv("RTP_SCENE_CACHE", "")
    assert scenes.default_cache_dir() == str(Path.home() / ".cache" / "rtp" / "scenes")
    monkeypatch.delenv("RTP_SCENE_CACHE")
    assert scenes.default_cache_dir() == str(Path.home() / ".cache" / "rtp" / "scenes")
    monkeypatch.setenv("RTP_SCENE_CACHE", "/somewhere/scenes")
    assert scenes.default_cache_dir() == "/somewhere/scenes"
    # a quoted ~ (RTP_SCENE_CACHE="~/scenes"): the home folder, not a folder named ~ in the current one
    monkeypatch.setenv("RTP_SCENE_CACHE", "~/scenes")
    assert scenes.default_cache_dir() == str(Path.home() / "scenes")


def test_fetch_takes_one_map_name_and_names_the_split_file_used(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """``fetch(cache, maps="m1")`` iterated over the letters of the name (UnlistedMapError 'm'); a listed map
    missing from the packages was said to be "listed in scenes.yaml" whatever split file was used."""
    splits = tmp_path / "s1.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    _fake_apt(monkeypatch, _packages())
    assert scenes.fetch(cache, "m1", splits=splits, progress=False) == {"m1": cache / "root" / OA / "map-m1.pk3"}
    with pytest.raises(scenes.FetchError, match=rf"maps listed in {re.escape(str(splits))} but not found in the "
                                                r"packages .*: \['m3'\]"):
        scenes.fetch(cache, "m3", splits=splits, progress=False)
    with pytest.raises(sdk.ParameterError, match=r"maps: expected a map name or a list of map names, got \[3\]"):
        scenes.fetch(cache, [3], splits=splits, progress=False)  # type: ignore[list-item]


def test_the_texture_group_does_not_depend_on_the_folders_above_the_cache(tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch):
    """The OpenArena group was decided from the absolute path: a cache under a folder named ``openarena``
    (``--cache-dir /tmp/x/openarena/c``) put every archive in it, and 20kdm2 converted with the OpenArena
    textures. It is decided from the path inside the unpacked packages."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "openarena" / "baseoa" / "cache"
    _fake_apt(monkeypatch, _packages())
    scenes.fetch(cache, ["m1", "m2"], splits=splits, progress=False)
    m1, tex, m2 = f"root/{OA}/map-m1.pk3", f"root/{OA}/pak-tex.pk3", "pk3/map-m2.pk3"
    assert json.loads((cache / "index.json").read_text())["groups"] == {"openarena": [m1, tex], "map-m2": [m2]}
    assert scene_by_name("m2", cache, splits=splits).materials[0].texture is None  # its own archive only
    assert scene_by_name("m1", cache, splits=splits).materials[0].texture is not None


def test_a_damaged_archive_of_the_cache_is_made_again_or_named_with_what_to_delete(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    """A ``.pk3`` gunzipped into ``<cache>/pk3`` and cut short (a full disk) was never made again: every later
    fetch failed on it. It is gunzipped again where it is not a zip archive. An archive unpacked into
    ``root/`` that is damaged is not unpacked again (the record of unpacked packages says it was): the
    error says exactly what to delete (it said "`rtp scenes fetch --cache-dir` an empty folder"), and doing
    so mends it."""
    splits = tmp_path / "scenes.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    _fake_apt(monkeypatch, _packages())
    scenes.fetch(cache, ["m1", "m2"], splits=splits, progress=False)
    cut = cache / "pk3" / "map-m2.pk3"
    whole = cut.read_bytes()
    cut.write_bytes(whole[: len(whole) // 2])
    assert scenes.fetch(cache, ["m2"], splits=splits, progress=False) == {"m2": cut}
    assert cut.read_bytes() == whole and scene_by_name("m2", cache, splits=splits).triangle_count == 79
    advice = re.escape(f"delete {cache / 'root' / '.unpacked'} and the folder {cache / 'pk3'}, then run "
                       f"`rtp scenes fetch --cache-dir {cache}` again")
    m1 = cache / "root" / OA / "map-m1.pk3"
    good = m1.read_bytes()
    m1.write_bytes(b"not a zip")
    with pytest.raises(scenes.FetchError, match=rf"map-m1.pk3 is not a pk3 \(zip\) archive .*: {advice}"):
        scenes.fetch(cache, ["m1"], splits=splits, progress=False)
    m1.write_bytes(good)
    damage_zip_member(m1, "maps/m1.bsp")
    (cache / "converted" / f"m1.v{CACHE_VERSION}.npz").unlink(missing_ok=True)
    with pytest.raises(SceneFormatError, match=rf"maps/m1.bsp in .*map-m1.pk3 is damaged .*: replace the archive "
                                               rf"\(in the fetched cache: {advice}"):
        scene_by_name("m1", cache, splits=splits)
    (cache / "root" / ".unpacked").unlink()  # what the message says
    shutil.rmtree(cache / "pk3")
    scenes.fetch(cache, ["m1", "m2"], splits=splits, progress=False)
    assert scene_by_name("m1", cache, splits=splits).triangle_count == 79


def _fake_cache(tmp_path: Path) -> Path:
    """A fetched cache whose one archive holds the tiny map as the listed map oa_dm1."""
    cache = tmp_path / "cache"
    (cache / "pk3").mkdir(parents=True)
    with zipfile.ZipFile(cache / "pk3" / "x.pk3", "w") as z:
        z.writestr("maps/oa_dm1.bsp", write_test_bsp())
    index = {"version": 1, "maps": {"oa_dm1": "pk3/x.pk3"}, "groups": {"x": ["pk3/x.pk3"]}}
    (cache / "index.json").write_text(json.dumps(index))
    return cache


def test_unreadable_converted_cache_is_rebuilt(tmp_path: Path, caplog: pytest.LogCaptureFixture):
    """A converted-scene file that is empty, truncated or not an npz is ignored (with a warning) and
    rebuilt, not an EOFError or zipfile.BadZipFile."""
    cache = _fake_cache(tmp_path)
    good = scene_by_name("oa_dm1", cache)
    path = cache / "converted" / f"oa_dm1.v{CACHE_VERSION}.npz"
    whole = path.read_bytes()
    for damaged in (b"", whole[: len(whole) // 2], b"junk" * 8):
        path.write_bytes(damaged)
        caplog.clear()
        with caplog.at_level("WARNING", logger="rtp"):
            assert scene_by_name("oa_dm1", cache).triangle_count == good.triangle_count
        assert any("ignoring unreadable cache" in r.getMessage() for r in caplog.records)
        assert load_scene_npz(path)[0].triangle_count == good.triangle_count


def _with_meta(path: Path, change) -> None:
    """Rewrite the converted-scene file ``path`` with its JSON header changed by ``change(meta)``, which returns
    the new header."""
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["meta"] = np.array(json.dumps(change(json.loads(str(arrays["meta"])))))
    with open(path, "wb") as f:
        np.savez(f, **arrays)


def _unknown_material_key(meta: dict) -> dict:
    meta["materials"][0]["shininess"] = 3
    return meta


@pytest.mark.parametrize("change", [
    _unknown_material_key,  # Material(**d): a TypeError
    lambda meta: meta | {"sun": None},  # None["direction"]: a TypeError
    lambda meta: [meta],  # a list: an AttributeError (list.get)
    lambda meta: meta | {"materials": {"0": {}}},  # a dict for the list: an AttributeError (str.pop)
    lambda meta: meta | {"point_lights": [{"position": [0, 0, 0]}]},  # a KeyError
    lambda meta: meta | {"ambient": -1.0},  # out of its range: the scene model's ParameterError
    lambda meta: meta | {"meshes": [0, 0, 0, 0, 0, 0, 0, 0, 0]},  # arrays it does not hold: a KeyError
    lambda meta: meta | {"stats": []},
], ids=["material-key", "sun-null", "list", "materials-dict", "light-fields", "ambient", "meshes", "stats"])
def test_a_converted_scene_with_a_header_of_another_shape_is_converted_again(tmp_path: Path, change,
                                                                           caplog: pytest.LogCaptureFixture):
    """docs/scenes.md: "a converted .npz that cannot be read is converted again, with a warning". A header of
    another shape (an unknown material field, "sun": null, a list for the object, ...) raised TypeError or
    AttributeError tracebacks: load_scene_npz now says SceneFormatError naming the file, and the map is
    converted again."""
    cache = _fake_cache(tmp_path)
    good = scene_by_name("oa_dm1", cache)
    path = cache / "converted" / f"oa_dm1.v{CACHE_VERSION}.npz"
    _with_meta(path, change)
    with pytest.raises(SceneFormatError, match=rf"{path.name}: "):
        load_scene_npz(path)
    with caplog.at_level("WARNING", logger="rtp"):
        assert scene_by_name("oa_dm1", cache).triangle_count == good.triangle_count
    assert any("ignoring unreadable cache" in r.getMessage() for r in caplog.records)
    assert load_scene_npz(path)[0].triangle_count == good.triangle_count  # written again


@pytest.mark.parametrize("sky", [
    np.zeros(4, np.float32),  # not triangles
    np.zeros((2, 3, 2), np.float32),  # 2-D vertices
    np.full((2, 3, 3), np.nan, np.float32),  # not finite
    np.array(["a"]),  # not numbers
], ids=["flat", "2d", "nan", "text"])
def test_a_converted_scene_with_damaged_sky_triangles_is_converted_again(tmp_path: Path, sky: np.ndarray,
                                                                         caplog: pytest.LogCaptureFixture):
    """The sky triangles of a converted .npz were returned whatever their shape: scene_blockers gave the
    capture a (4,) or NaN array and sample_viewpoints failed on it ("blockers: expected finite triangles"),
    where any other damage of the file converts the map again. Now load_scene_npz says SceneFormatError
    naming the file, the map is converted again (with a warning), and save_scene_npz refuses to write such
    triangles (a ParameterError naming ``sky``)."""
    cache = _fake_cache(tmp_path)
    good = scenes.scene_blockers("oa_dm1", cache)
    assert good.shape[1:] == (3, 3) and len(good)
    path = cache / "converted" / f"oa_dm1.v{CACHE_VERSION}.npz"
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["sky"] = sky
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    with pytest.raises(SceneFormatError, match=rf"{path.name}: its sky triangles are .* not finite floats"):
        load_scene_npz(path)
    with caplog.at_level("WARNING", logger="rtp"):
        np.testing.assert_array_equal(scenes.scene_blockers("oa_dm1", cache), good)
    assert any("ignoring unreadable cache" in r.getMessage() for r in caplog.records)
    np.testing.assert_array_equal(load_scene_npz(path)[1], good)  # written again
    with pytest.raises(sdk.ParameterError, match=r"sky: expected finite triangles of shape \(K, 3, 3\)"):
        save_scene_npz(tmp_path / "x.npz", scenes.procedural(0), sky)
    assert not (tmp_path / "x.npz").exists()


def test_a_converted_scene_that_cannot_be_cached_is_still_returned(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                   caplog: pytest.LogCaptureFixture):
    """A cache folder that is read-only (a shared cache) or on a full disk: scene_by_name converted the map, then
    failed writing ``converted/<map>.npz`` with the system's error, and the scene was lost. The scene is returned,
    with a warning that it could not be cached, and nothing half-written is left."""
    import errno

    cache = _fake_cache(tmp_path)

    def read_only(path, *args, **kw):  # noqa: ANN001, ANN002, ANN003
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(scenes._fetch, "save_scene_npz", read_only)
    with caplog.at_level("WARNING", logger="rtp"):
        assert scene_by_name("oa_dm1", cache).triangle_count == 79
        assert scenes.scene_blockers("oa_dm1", cache).shape[1:] == (3, 3)
    assert "could not cache the converted scene 'oa_dm1' ([Errno 13] Permission denied" in caplog.text
    assert not (cache / "converted").exists() or not list((cache / "converted").iterdir())


def test_scene_index_and_split_file_errors(tmp_path: Path, caplog: pytest.LogCaptureFixture):
    """A scene index that is not JSON (nor UTF-8), not an object, lacks its tables or is of another version
    (that one was a SceneNotFoundError whose advice lacked the cache folder) is SceneFormatError, each saying
    to fetch again into the cache folder used, and scene_list still lists the maps as not fetched, with a
    warning saying why (it said nothing: `rtp scenes list` read "0 fetched: run `rtp scenes fetch`"); a listed
    map missing from the cache is SceneNotFoundError; a split file with unknown keys is SceneFormatError; an
    unknown split name is an sdk.ParameterError naming ``split`` (it was UnlistedMapError)."""
    import re

    cache = _fake_cache(tmp_path)
    index = cache / "index.json"
    again = re.escape(f"run `rtp scenes fetch --cache-dir {cache}` again")
    for text, message in [("{trunc", "is not a scene index .*Expecting"),
                          (b"\xff\xfe{", "is not a scene index .*can't decode"),
                          ("[]", "is not a scene index \\(a JSON list"),
                          ('{"version": 1}', "lacks the 'maps' or 'groups' table"),
                          ('{"version": 0, "maps": {}, "groups": {}}',
                           "was written by another rtp version \\(index version 0, this rtp reads 1\\)")]:
        index.write_bytes(text if isinstance(text, bytes) else text.encode())
        with pytest.raises(SceneFormatError, match=f"{message}.*: {again}"):
            scene_by_name("oa_dm1", cache)
        caplog.clear()
        with caplog.at_level("WARNING", logger="rtp"):
            assert not any(m["fetched"] for m in scenes.scene_list(cache))
        assert [r.getMessage() for r in caplog.records if "the scene index is damaged or out of date" in r.getMessage()
                and re.search(f"{message}.*: {again}", r.getMessage())], caplog.text
    caplog.clear()
    with caplog.at_level("WARNING", logger="rtp"):  # nothing fetched yet: nothing to warn about
        assert not any(m["fetched"] for m in scenes.scene_list(tmp_path / "empty"))
    assert not caplog.records
    index.write_text(json.dumps({"version": 1, "maps": {"oa_dm1": "pk3/x.pk3"}, "groups": {}}))
    with pytest.raises(SceneNotFoundError, match="'oa_dm2' is not in the scene cache"):
        scenes.check_map("oa_dm2", cache)
    with pytest.raises(SceneNotFoundError, match="'oa_dm2' is not in the fetched packages"):
        scenes._fetch.convert_from_cache("oa_dm2", cache)
    extra = tmp_path / "extra.yaml"
    extra.write_text("train: [a]\nvalidation: []\ntest: []\nholdout: [b]\n")
    with pytest.raises(SceneFormatError, match=r"unknown keys \['holdout'\]"):
        load_splits(extra)
    # a misspelt split is named as such (it read "'train' must be a list of map names, got None"), a missing one too
    for text, message in (("trian: [a]\nvalidation: []\ntest: []\n", r"unknown keys \['trian'\]"),
                          ("validation: []\ntest: []\n", r"no 'train' split; expected the keys")):
        extra.write_text(text)
        with pytest.raises(SceneFormatError, match=message):
            load_splits(extra)
    for bad in ("training", "Train"):
        with pytest.raises(sdk.ParameterError, match=rf"split: expected one of train, validation, test \(or None for "
                                                     rf"every split\), got '{bad}'") as e:
            scenes.map_names(bad)
        assert e.value.name == "split"
    with pytest.raises(sdk.ParameterError, match="split: expected one of") as e:
        scene_by_name("oa_dm1", cache, split="bogus")
    assert e.value.name == "split"
    assert scene_by_name("oa_dm1", cache, split="train").triangle_count > 0


def test_fetch_refuses_an_empty_or_non_iterable_maps_before_any_download(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch):
    """``fetch(cache, [])`` downloaded and unpacked every package (~177 MB of .debs, ~400 MB on disk) and
    returned ``{}``; ``fetch(cache, 5)`` was a bare TypeError where the docstring promises a ParameterError."""
    calls = _fake_apt(monkeypatch, _packages())
    splits = tmp_path / "s.yaml"
    splits.write_text(SPLITS)
    for maps, shown in (([], "an empty list"), ((), "an empty tuple"), (iter(()), "an empty tuple_iterator"), (5, "5")):
        with pytest.raises(sdk.ParameterError, match=rf"maps: expected .*got {shown}") as err:
            scenes.fetch(tmp_path / "cache", maps, splits=splits, progress=False)  # type: ignore[arg-type]
        assert err.value.name == "maps"
    assert calls == [] and not (tmp_path / "cache").exists()


def test_a_map_name_that_is_not_text_is_a_parameter_error(tmp_path: Path):
    """``scene_by_name(5, cache)`` (or None, or a list of names) raised a bare ``TypeError: 'int' object is not
    iterable`` from the suggestions of close names; the scene functions' errors are typed."""
    for call in (lambda n: scene_by_name(n, tmp_path), lambda n: scenes.scene_blockers(n, tmp_path),
                 lambda n: scenes.check_map(n, tmp_path)):
        for name in (5, None, ["oa_dm1"]):
            with pytest.raises(sdk.ParameterError, match=r"name: expected a map name .*got") as err:
                call(name)
            assert err.value.name == "name"


def test_a_map_listed_twice_in_one_split_is_named_so(tmp_path: Path):
    """A map listed twice in one split was said to be "in both 'train' and 'train'"."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("train: [a, b, a]\nvalidation: []\ntest: []\n")
    with pytest.raises(SceneFormatError, match=r"map 'a' is listed twice in 'train'$"):
        load_splits(bad)


def test_a_scene_cache_that_is_a_file_is_refused(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]):
    """`rtp scenes list --cache-dir FILE` said "59 maps, 0 fetched: run `rtp scenes fetch`", and the fetch it
    pointed at failed with the system's "Not a directory: 'FILE/debs'": both say the cache is a file."""
    from rtp.cli import main

    calls = _fake_apt(monkeypatch, _packages())
    splits = tmp_path / "s.yaml"
    splits.write_text(SPLITS)
    cache = tmp_path / "cache"
    cache.write_text("not a folder")
    for call in (lambda: scenes.scene_list(cache, splits), lambda: scenes.fetch(cache, splits=splits, progress=False)):
        with pytest.raises(sdk.ParameterError, match=r"cache_dir: expected the scene cache's folder .*which is a file") as err:
            call()
        assert err.value.name == "cache_dir"
    assert calls == [] and cache.read_text() == "not a folder"
    for command in ("list", "fetch"):
        assert main(["scenes", command, "--cache-dir", str(cache), "--splits", str(splits)]) == 2
        assert "--cache-dir: expected the scene cache's folder" in capsys.readouterr().err
