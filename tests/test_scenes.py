"""Scene sources: procedural generator, Quake-3 BSP importer (on a BSP the test writes), glTF/OBJ
through trimesh, the split list and the converted-scene cache. No network."""

from __future__ import annotations

import io
import json
import math
import struct
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

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
from rtp.capture.scenes._cache import load_scene_npz, save_scene_npz
from rtp.capture.scenes._materials import pbr_for_path
from rtp.capture.scenes._pk3 import parse_shaders
from rtp.sdk import RtpError

PIL = pytest.importorskip("PIL.Image")


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
    trimesh = pytest.importorskip("trimesh")
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
