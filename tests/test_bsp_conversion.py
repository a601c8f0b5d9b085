"""The BSP conversion rules of docs/scenes.md that the tiny map of test_scenes.py does not reach:
dropped surfaces, alpha tests, emission, the light fallbacks (entities, surface lights, light-looking
textures, lights above the spawns), the sun and the sky colour; the patch, normal, entity, texture and sky
fallbacks; and the malformed files (BSP lumps and faces, sources, damaged pk3 members) that must raise
SceneFormatError. Each case is a synthetic map."""

from __future__ import annotations

import io
import math
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rtp.capture.scenes import SceneFormatError, convert_bsp
from rtp.capture.scenes._bsp import FACE_DT, TEXTURE_DT, UNIT, VERTEX_DT
from rtp.scene import Scene, SunLight
from rtp.sdk import srgb_to_linear

from .conftest import damage_zip_member

SURF_SKY, SURF_NODRAW, CONTENTS_FOG = 0x4, 0x80, 0x40

SHADERS = """
textures/test/glow
{
    q3map_surfacelight 400
    q3map_lightRGB 1 0.8 0.5
    {
        map textures/test/glow.png
    }
}
textures/test/fence
{
    {
        map textures/test/fence.png
        alphaFunc GE128
    }
}
textures/test/gt0
{
    {
        map textures/test/fence.png
        alphaFunc GT0
    }
}
textures/test/blended
{
    {
        map textures/test/fence.png
        blendFunc blend
    }
    {
        map $lightmap
        blendFunc filter
    }
}
textures/test/solidblend
{
    {
        map textures/test/wall.png
        blendFunc blend
    }
    {
        map $lightmap
        blendFunc filter
    }
}
textures/test/flare
{
    {
        map textures/test/wall.png
        blendFunc add
    }
}
textures/test/fogvol
{
    surfaceparm fog
}
textures/skies/sky2
{
    surfaceparm sky
    q3map_sunExt 0.9 0.8 1 250 120 35 2 16
    skyparms env/sky2 512 -
}
"""

WALL_RGB, LAVA_RGB, SKY_RGB = (200, 30, 30), (240, 90, 10), (100, 150, 230)
LUM709 = np.array([0.2126, 0.7152, 0.0722])


def _png(rgba: tuple[int, ...], transparent_corner: bool = False) -> bytes:
    im = Image.new("RGBA", (8, 8), (*rgba[:3], 255))
    if transparent_corner:
        im.putpixel((0, 0), (*rgba[:3], 0))
    buf = io.BytesIO()
    im.save(buf, format="PNG")
    return buf.getvalue()


def _quad(x0: float, y0: float, size: float, z: float, up: bool) -> tuple[list, list[int]]:
    """A square at height ``z`` (Q3 units) facing +Z (``up``) or -Z, as vertices and CW meshverts."""
    n = (0.0, 0.0, 1.0 if up else -1.0)
    vs = [((x0, y0, z), (0, 0), n), ((x0 + size, y0, z), (1, 0), n),
          ((x0 + size, y0 + size, z), (1, 1), n), ((x0, y0 + size, z), (0, 1), n)]
    return vs, ([0, 3, 2, 0, 2, 1] if up else [0, 1, 2, 0, 2, 3])


def _map(textures: list[tuple[str, int, int]], entities: str) -> bytes:
    """An IBSP v46 map with one 64-unit square per texture ``(name, flags, contents)``, the i-th at
    x = 100 i, facing down from z = 128; ``entities`` is the entity lump's text."""
    faces = []
    for i in range(len(textures)):
        vs, mv = _quad(100.0 * i, 0.0, 64.0, 128.0, up=False)
        faces.append((1, i, vs, mv, (0, 0)))
    return _faces_map(textures, faces, entities)


#: A face of :func:`_faces_map`: type (1 polygon, 2 patch, 3 mesh), texture index, vertices
#: ``[(pos, uv, normal)]``, meshverts, patch size ``(width, height)``.
Face = tuple[int, int, list, list[int], tuple[int, int]]


def _faces_map(textures: list[tuple[str, int, int]], faces: list[Face], entities: str) -> bytes:
    """An IBSP v46 map of ``faces`` over ``textures`` ``(name, flags, contents)``."""
    tex = np.zeros(len(textures), TEXTURE_DT)
    tex["name"] = [t[0].encode() for t in textures]
    tex["flags"] = [t[1] for t in textures]
    tex["contents"] = [t[2] for t in textures]
    verts: list = []
    meshverts: list[int] = []
    farr = np.zeros(len(faces), FACE_DT)
    for i, (ftype, t, vs, mv, size) in enumerate(faces):
        farr[i]["texture"], farr[i]["type"], farr[i]["vertex"], farr[i]["n_vertexes"] = t, ftype, len(verts), len(vs)
        farr[i]["meshvert"], farr[i]["n_meshverts"], farr[i]["size"] = len(meshverts), len(mv), size
        verts += vs
        meshverts += mv
    varr = np.zeros(len(verts), VERTEX_DT)
    for i, (pos, uv, n) in enumerate(verts):
        varr[i]["pos"], varr[i]["uv"], varr[i]["normal"], varr[i]["color"] = pos, uv, n, (255, 255, 255, 255)
    lumps = [b""] * 17
    lumps[0], lumps[1], lumps[10] = entities.encode() + b"\0", tex.tobytes(), varr.tobytes()
    lumps[11], lumps[13] = np.asarray(meshverts, "<i4").tobytes(), farr.tobytes()
    body, directory = b"", []
    for lump in lumps:
        directory.append((8 + 17 * 8 + len(body), len(lump)))
        body += lump + b"\0" * (-len(lump) % 4)
    return b"IBSP" + struct.pack("<i", 46) + b"".join(struct.pack("<ii", *d) for d in directory) + body


SPAWN = '{\n"classname" "info_player_deathmatch"\n"origin" "32 16 8"\n"angle" "90"\n}\n'


def _pk3(path: Path, textures: list[tuple[str, int, int]], entities: str = SPAWN, shaders: str = SHADERS,
         faces: list[Face] | None = None, extra: dict[str, bytes] | None = None) -> Path:
    """A pk3 of map ``maps/m.bsp`` (one square per texture, or ``faces``), the test images, the
    shader script and the ``extra`` files (stored, not compressed)."""
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("maps/m.bsp", _map(textures, entities) if faces is None else _faces_map(textures, faces, entities))
        for name, data in (extra or {}).items():
            z.writestr(name, data)
        z.writestr("textures/test/wall.png", _png(WALL_RGB))
        z.writestr("textures/test/glow.png", _png((250, 250, 200)))
        z.writestr("textures/test/lava_1.png", _png(LAVA_RGB))
        z.writestr("textures/test/torch.png", _png((255, 120, 20)))
        z.writestr("textures/test/fence.png", _png((120, 120, 120), transparent_corner=True))
        z.writestr("env/sky2_up.png", _png(SKY_RGB))
        z.writestr("scripts/test.shader", shaders)
    return path


RICH = [
    ("textures/test/wall", 0, 1), ("textures/test/glow", 0, 1), ("textures/test/lava_1", 0, 1),
    ("textures/test/fence", 0, 1), ("textures/test/gt0", 0, 1), ("textures/test/blended", 0, 1),
    ("textures/test/solidblend", 0, 1),
    # dropped: a shader of blended stages only, tool texture, nodraw flag, fog contents, noshader; then the sky
    ("textures/test/flare", 0, 1), ("textures/common/clip", 0, 1), ("textures/test/nodraw", SURF_NODRAW, 1),
    ("textures/test/fogvol", 0, CONTENTS_FOG), ("noshader", 0, 1), ("textures/skies/sky2", SURF_SKY, 1),
]


def test_dropped_surfaces_alpha_tests_and_emission(tmp_path: Path) -> None:
    conv = convert_bsp(_pk3(tmp_path / "rich.pk3", RICH))
    mats = {m.name.rsplit("/", 1)[-1]: m for m in conv.scene.materials}
    assert list(mats) == ["wall", "glow", "lava_1", "fence", "gt0", "blended", "solidblend"]
    assert conv.stats["dropped_faces"] == 5 and conv.stats["sky_faces"] == 1 and len(conv.sky_triangles) == 2
    assert conv.missing_textures == []
    # alphaFunc GE128 / GT0 and an alpha-blend stage (beside a lightmap) cut; over an opaque image nothing is cut
    assert (mats["fence"].alpha_cutoff, mats["gt0"].alpha_cutoff, mats["blended"].alpha_cutoff) == (0.5, 0.05, 0.5)
    assert mats["fence"].texture[0, 0, 3] == 0
    for name in ("wall", "solidblend", "lava_1"):
        assert mats[name].alpha_cutoff is None and (mats[name].texture[..., 3] == 255).all()
    # emission: a surface light shines its q3map_lightRGB (normalised) x 1.5; lava its linear mean colour x 2
    assert mats["glow"].emissive == pytest.approx((1.5, 1.2, 0.75))
    np.testing.assert_allclose(mats["lava_1"].emissive, 2.0 * srgb_to_linear(np.array(LAVA_RGB) / 255.0))
    assert mats["wall"].emissive == (0.0, 0.0, 0.0)


def test_alpha_func_lt128_keeps_the_texels_below_128(tmp_path: Path) -> None:
    """alphaFunc LT128 keeps the texels whose alpha is below 128; it got the GE128 cutoff over the image's
    own alpha, so the renderer (which discards alpha below the cutoff) drew the holes and cut the rest. The
    alpha channel is now inverted for it: the fence's one transparent texel is the only one drawn."""
    shaders = SHADERS + "textures/test/lt\n{\n    {\n        map textures/test/fence.png\n        alphaFunc LT128\n    }\n}\n"
    conv = convert_bsp(_pk3(tmp_path / "lt.pk3", [("textures/test/lt", 0, 1), ("textures/test/fence", 0, 1)],
                            shaders=shaders))
    lt, fence = conv.scene.materials
    assert lt.alpha_cutoff == fence.alpha_cutoff == 0.5
    kept_lt, kept_fence = lt.texture[..., 3] / 255.0 >= 0.5, fence.texture[..., 3] / 255.0 >= 0.5
    assert kept_lt.sum() == 1 and kept_lt[0, 0]  # (the image: opaque but for its corner texel)
    assert (kept_lt == ~kept_fence).all()


def test_surface_lights_sun_and_sky_colour(tmp_path: Path) -> None:
    scene = convert_bsp(_pk3(tmp_path / "rich.pk3", RICH)).scene
    # no light entities: one light at the glow square (texture 1, 64 units at x = 100..164, z = 128,
    # facing down), 0.3 m below its centre, power = area x surface light
    (light,) = scene.point_lights
    centre = np.array([132.0, 128.0, -32.0]) * UNIT
    np.testing.assert_allclose(light.position, centre + [0.0, -0.3, 0.0], atol=1e-6)
    assert light.colour == pytest.approx((1.0, 0.8, 0.5))
    value = 300.0 * math.sqrt((64 * UNIT) ** 2 * 400.0 / 300.0)
    assert light.intensity == pytest.approx(value / 30.0)
    assert light.radius == pytest.approx(value * 1.5 * UNIT)
    # q3map_sunExt r g b intensity azimuth elevation: colour normalised, 3 x intensity / 100 clamped to 6
    assert scene.sun.colour == pytest.approx((0.9, 0.8, 1.0)) and scene.sun.intensity == 6.0
    a, e = math.radians(120.0), math.radians(35.0)
    to_sun_q3 = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    np.testing.assert_allclose(scene.sun.direction, -np.array([to_sun_q3[0], to_sun_q3[2], -to_sun_q3[1]]), atol=1e-9)
    # the sky colour: the far box top's hue, half desaturated, at the default sky luminance
    m = srgb_to_linear(np.array(SKY_RGB) / 255.0)
    default = np.asarray(Scene.__dataclass_fields__["sky_colour"].default)
    np.testing.assert_allclose(scene.sky_colour, (0.5 * m / (m @ LUM709) + 0.5) * (default @ LUM709))


def test_light_entities_keep_the_strongest(tmp_path: Path) -> None:
    lights = "".join(f'{{\n"classname" "light"\n"origin" "{10 * i} 0 64"\n"light" "{v}"\n"_color" "1 0.5 0.25"\n}}\n'
                     for i, v in enumerate((200, 900, 450, 300, 600)))
    scene = convert_bsp(_pk3(tmp_path / "lit.pk3", RICH, SPAWN + lights), max_point_lights=3).scene
    assert [round(pl.intensity * 30) for pl in scene.point_lights] == [900, 600, 450]
    assert scene.point_lights[0].position == pytest.approx((10 * UNIT, 64 * UNIT, 0.0))
    assert scene.point_lights[0].colour == pytest.approx((1.0, 0.5, 0.25))


def test_light_fallbacks(tmp_path: Path) -> None:
    plain = SHADERS.replace("q3map_surfacelight 400", "")
    # no surface-light shader: textures that look like lights glow with value 500
    torch = [("textures/test/wall", 0, 1), ("textures/test/torch", 0, 1)]
    (light,) = convert_bsp(_pk3(tmp_path / "torch.pk3", torch, shaders=plain)).scene.point_lights
    value = 300.0 * math.sqrt((64 * UNIT) ** 2 * 500.0 / 300.0)
    assert light.intensity == pytest.approx(value / 30.0)
    np.testing.assert_allclose(light.position, np.array([132.0, 128.0, -32.0]) * UNIT + [0.0, -0.3, 0.0], atol=1e-6)
    # nothing emits: one white light 1 m above each spawn point (at most max_point_lights)
    spawns = SPAWN + SPAWN.replace("32 16 8", "200 40 8")
    scene = convert_bsp(_pk3(tmp_path / "dark.pk3", torch[:1], spawns, shaders=plain), max_point_lights=1).scene
    assert len(scene.spawn_points) == 2 and len(scene.point_lights) == 1
    (light,) = scene.point_lights
    np.testing.assert_allclose(light.position, np.asarray(scene.spawn_points[0].position) + [0.0, 1.0, 0.0])
    assert light.colour == (1.0, 1.0, 1.0) and light.intensity == pytest.approx(400.0 / 30.0)


def test_missing_images_warn_once_per_map(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    textures = [("textures/test/wall", 0, 1)] + [(f"textures/gone/t{i}", 0, 1) for i in range(5)]
    with caplog.at_level("WARNING", logger="rtp"):
        conv = convert_bsp(_pk3(tmp_path / "gone.pk3", textures))
    assert conv.missing_textures == [f"textures/gone/t{i}" for i in range(5)]
    warnings = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert len(warnings) == 1 and "5 textures have no image" in warnings[0] and "and 2 more" in warnings[0]
    assert sum(m.base_color == (0.5, 0.5, 0.5, 1.0) for m in conv.scene.materials) == 5


# -- patches, normals, entities, sky and texture fallbacks ----------------------------------------------

def _grid(x0: float, z: float, up: bool, w: int = 3, h: int = 3) -> list:
    """A flat ``w`` x ``h`` patch control grid (row-major, 32-unit spacing) at height ``z`` whose
    normals face +Z (``up``) or -Z."""
    n = (0.0, 0.0, 1.0 if up else -1.0)
    return [((x0 + 32.0 * c, 32.0 * r, z), (c / (w - 1), r / max(h - 1, 1)), n) for r in range(h) for c in range(w)]


def _facing(mesh) -> np.ndarray:
    """Each triangle's geometric normal (unit, world space)."""
    p = mesh.positions[mesh.indices.astype(np.int64)]
    g = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return g / np.linalg.norm(g, axis=1, keepdims=True)


def test_patches_face_their_normals_and_malformed_patches_are_skipped(tmp_path: Path) -> None:
    """A bezier patch is wound so its triangles face the way its vertex normals do, whichever way the
    control grid runs; patches of even or too small size, or with fewer control points than the size
    needs, are skipped (no triangles, not counted), not a crash."""
    textures = [("textures/test/up", 0, 1), ("textures/test/down", 0, 1), ("textures/test/even", 0, 1),
                ("textures/test/short", 0, 1)]
    faces: list[Face] = [(2, 0, _grid(0.0, 0.0, up=True), [], (3, 3)),
                         (2, 1, _grid(200.0, 64.0, up=False), [], (3, 3)),
                         (2, 2, _grid(400.0, 0.0, up=True, w=4), [], (4, 3)),
                         (2, 3, _grid(600.0, 0.0, up=True)[:8], [], (3, 3))]
    conv = convert_bsp(_pk3(tmp_path / "patches.pk3", textures, faces=faces), patch_level=4)
    assert conv.stats["patches"] == 2
    assert [m.name for m in conv.scene.materials] == ["textures/test/up", "textures/test/down"]
    up, down = conv.scene.meshes
    assert len(up.indices) == len(down.indices) == 4 * 4 * 2
    np.testing.assert_allclose(up.normals, [[0.0, 1.0, 0.0]] * len(up.normals), atol=1e-6)
    np.testing.assert_allclose(_facing(up), [[0.0, 1.0, 0.0]] * len(up.indices), atol=1e-6)
    np.testing.assert_allclose(down.normals, [[0.0, -1.0, 0.0]] * len(down.normals), atol=1e-6)
    np.testing.assert_allclose(_facing(down), [[0.0, -1.0, 0.0]] * len(down.indices), atol=1e-6)


def test_a_patch_size_whose_product_overflows_int32_is_skipped(tmp_path: Path) -> None:
    """A patch of size 3 x 1431655769 needs 4294967307 control points, which int32 arithmetic on the face
    lump's fields wrapped to 11: with 11 control points it passed the size check and numpy's reshape failed
    (a bare ValueError out of convert_bsp). It is now skipped like any patch with fewer control points than
    its size needs, and the rest of the map converts."""
    textures = [("textures/test/up", 0, 1), ("textures/test/huge", 0, 1)]
    faces: list[Face] = [(2, 0, _grid(0.0, 0.0, up=True), [], (3, 3)),
                         (2, 1, _grid(200.0, 0.0, up=True, h=5)[:11], [], (3, 1431655769))]
    conv = convert_bsp(_pk3(tmp_path / "huge.pk3", textures, faces=faces), patch_level=2)
    assert conv.stats["patches"] == 1
    assert [m.name for m in conv.scene.materials] == ["textures/test/up"]


def test_sky_patches_seal_the_level(tmp_path: Path) -> None:
    """A curved sky (a patch on a sky texture) is not drawn but tessellated at level 2 into the
    blocker triangles, in world metres; a map of patches only converts."""
    textures = [("textures/test/wall", 0, 1), ("textures/skies/dome", SURF_SKY, 1)]
    faces: list[Face] = [(2, 0, _grid(0.0, 0.0, up=True), [], (3, 3)), (2, 1, _grid(0.0, 512.0, up=False), [], (3, 3))]
    conv = convert_bsp(_pk3(tmp_path / "dome.pk3", textures, faces=faces))
    assert [m.name for m in conv.scene.materials] == ["textures/test/wall"]
    assert conv.sky_triangles.shape == (2 * 2 * 2, 3, 3) and conv.stats["sky_faces"] == 1
    np.testing.assert_allclose(conv.sky_triangles[..., 1], 512.0 * UNIT, rtol=1e-6)
    np.testing.assert_allclose([conv.sky_triangles[..., 0].max(), conv.sky_triangles[..., 2].min()],
                               [64.0 * UNIT, -64.0 * UNIT], rtol=1e-6)


def test_zero_vertex_normals_are_recomputed_from_the_faces(tmp_path: Path) -> None:
    """Vertices stored without a normal (zero vectors) get the normals of their faces."""
    vs, mv = _quad(0.0, 0.0, 64.0, 128.0, up=False)
    faces: list[Face] = [(1, 0, [(p, uv, (0.0, 0.0, 0.0)) for p, uv, _ in vs], mv, (0, 0))]
    (mesh,) = convert_bsp(_pk3(tmp_path / "flat.pk3", [("textures/test/wall", 0, 1)], faces=faces)).scene.meshes
    np.testing.assert_allclose(mesh.normals, [[0.0, -1.0, 0.0]] * 4, atol=1e-6)
    np.testing.assert_allclose(_facing(mesh), [[0.0, -1.0, 0.0]] * 2, atol=1e-6)


def test_malformed_entity_values_fall_back(tmp_path: Path) -> None:
    """Entity keys that do not parse: an unreadable angle faces 0 (yaw -90), an origin that is not
    three numbers drops the entity, an unreadable light value is 300 and an unreadable colour white;
    entities that are neither spawn points nor lights are ignored."""
    ents = ('{\n"classname" "info_player_start"\n"origin" "0 0 0"\n"angle" "east"\n}\n'
            '{\n"classname" "info_player_deathmatch"\n"origin" "10 20"\n}\n'
            '{\n"classname" "team_CTF_redspawn"\n"origin" "a b c"\n}\n'
            '{\n"classname" "item_health"\n"origin" "5 5 5"\n}\n'
            '{\n"classname" "light"\n"origin" "0 0 64"\n"light" "bright"\n"_color" "red"\n}\n')
    scene = convert_bsp(_pk3(tmp_path / "ents.pk3", [("textures/test/wall", 0, 1)], ents)).scene
    (spawn,) = scene.spawn_points
    assert spawn.position == pytest.approx((0.0, 35.0 * UNIT, 0.0)) and spawn.yaw == pytest.approx(-90.0)
    (light,) = scene.point_lights
    assert light.position == pytest.approx((0.0, 64.0 * UNIT, 0.0))
    assert light.colour == (1.0, 1.0, 1.0) and light.intensity == pytest.approx(10.0)



def test_spawn_yaw_reads_angles_as_the_game_does(tmp_path: Path) -> None:
    """The game sets a spawn point's facing from ``angle`` or from ``angles`` (pitch yaw roll), whichever
    the entity sets last: an ``angles`` spawn faced Q3 angle 0 (yaw -90) whatever it said."""
    spawn = '{{\n"classname" "info_player_deathmatch"\n"origin" "{x} 0 0"\n{keys}}}\n'
    ents = "".join(spawn.format(x=10 * i, keys=keys) for i, keys in enumerate((
        '"angles" "0 180 0"\n',  # yaw 180 -> 90
        '"angle" "45"\n"angles" "10 270 0"\n',  # angles set last: 270 -> 180 (wrapped to -180)
        '"angles" "0 270 0"\n"angle" "45"\n',  # angle set last: 45 -> -45
        '"angles" "30"\n',  # no yaw in it: passed over, 0 -> -90
    )))
    scene = convert_bsp(_pk3(tmp_path / "angles.pk3", [("textures/test/wall", 0, 1)], ents)).scene
    assert [sp.yaw for sp in scene.spawn_points] == pytest.approx([90.0, -180.0, -45.0, -90.0])


def test_light_entity_values_as_q3map2_reads_them(tmp_path: Path) -> None:
    """A light's value is q3map2's: ``_light`` before ``light``, a 0 falling back to the other and then to
    300; a negative (darkening) light is no point light (it shone as a weak bright one); a colour of zeros
    is white and a negative component none of that colour (``"1 -1 0"`` refused the whole map)."""
    light = '{{\n"classname" "light"\n"origin" "{x} 0 64"\n{keys}}}\n'
    ents = SPAWN + "".join(light.format(x=10 * i, keys=keys) for i, keys in enumerate((
        '"light" "600"\n"_light" "900"\n',  # _light wins: 900
        '"light" "0"\n',  # 0: the default 300
        '"_light" "0"\n"light" "450"\n',  # _light 0: light's 450
        '"light" "-500"\n',  # a dark light: none
        '"light" "200"\n"_color" "0 0 0"\n',  # white
        '"light" "150"\n"_color" "1 -1 0.5"\n',  # (1, 0, 0.5)
    )))
    scene = convert_bsp(_pk3(tmp_path / "values.pk3", [("textures/test/wall", 0, 1)], ents)).scene
    lights = scene.point_lights
    assert [round(pl.intensity * 30) for pl in lights] == [900, 300, 450, 200, 150]
    assert [pl.position[0] for pl in lights] == pytest.approx([0.0, 10 * UNIT, 20 * UNIT, 40 * UNIT, 50 * UNIT])
    assert lights[3].colour == (1.0, 1.0, 1.0) and lights[4].colour == pytest.approx((1.0, 0.0, 0.5))


SKY_SHADER = """
textures/skies/clouds
{{
    surfaceparm sky
    skyparms {farbox} 512 -
    {{
        map {image}
    }}
}}
"""


@pytest.mark.parametrize(("farbox", "image", "rgb"), [
    ("env/absent", "textures/skies/clouds.png", SKY_RGB),  # no far box images: the stage's image
    ("env/broken", "textures/skies/clouds.png", SKY_RGB),  # far box image undecodable: the stage's image
    ("env/absent", "textures/skies/black.png", None),  # a black sky gives no hue: the default sky colour
])
def test_sky_colour_fallbacks(tmp_path: Path, farbox: str, image: str, rgb: tuple[int, int, int] | None) -> None:
    """The sky colour comes from the first sky texture that has a shader (a sky texture without one is
    passed over): its far box top, else its first stage image; a shader without ``q3map_sun`` keeps the
    default sun."""
    textures = [("textures/test/wall", 0, 1), ("textures/skies/bare", SURF_SKY, 1), ("textures/skies/clouds", SURF_SKY, 1)]
    extra = {"env/broken_up.png": b"\x89PNG\r\n\x1a\n not an image", "textures/skies/clouds.png": _png(SKY_RGB),
             "textures/skies/black.png": _png((0, 0, 0))}
    shaders = SKY_SHADER.format(farbox=farbox, image=image)
    scene = convert_bsp(_pk3(tmp_path / "sky.pk3", textures, shaders=shaders, extra=extra)).scene
    assert scene.sun == SunLight()
    default = np.asarray(Scene.__dataclass_fields__["sky_colour"].default)
    if rgb is None:
        assert scene.sky_colour == tuple(default)
    else:
        m = srgb_to_linear(np.array(rgb) / 255.0)
        np.testing.assert_allclose(scene.sky_colour, (0.5 * m / (m @ LUM709) + 0.5) * (default @ LUM709))


TEXTURE_SHADERS = """
textures/test/edited
{
    qer_editorimage textures/test/wall.png
    {
        map textures/test/gone.tga
    }
}
textures/test/lamp
{
    q3map_surfacelight 400
}
"""


def test_texture_fallbacks(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """An image that does not decode gives a grey material (with a warning naming it); an image over
    1024 texels is halved until it fits; a shader whose stage image is missing falls back to its editor
    image; a surface light without any image shines white."""
    huge = io.BytesIO()
    Image.new("RGBA", (2048, 4), (10, 200, 10, 255)).save(huge, format="PNG")
    textures = [("textures/test/broken", 0, 1), ("textures/test/huge", 0, 1), ("textures/test/edited", 0, 1),
                ("textures/test/lamp", 0, 1)]
    extra = {"textures/test/broken.png": b"\x89PNG\r\n\x1a\n truncated", "textures/test/huge.png": huge.getvalue()}
    with caplog.at_level("WARNING", logger="rtp"):
        conv = convert_bsp(_pk3(tmp_path / "tex.pk3", textures, shaders=TEXTURE_SHADERS, extra=extra))
    assert any("could not decode texture textures/test/broken.png" in r.getMessage() for r in caplog.records)
    broken, huge_mat, edited, lamp = conv.scene.materials
    assert conv.missing_textures == ["textures/test/broken", "textures/test/lamp"]
    assert broken.texture is None and broken.base_color == (0.5, 0.5, 0.5, 1.0)
    assert huge_mat.texture is not None and huge_mat.texture.shape == (2, 1024, 4)
    assert tuple(huge_mat.texture[0, 0]) == (10, 200, 10, 255)
    assert edited.texture is not None and tuple(edited.texture[0, 0, :3]) == WALL_RGB
    assert lamp.texture is None
    (light,) = conv.scene.point_lights
    assert light.colour == (1.0, 1.0, 1.0)


def test_a_dot_in_a_texture_name_is_part_of_it(tmp_path: Path) -> None:
    """A name whose dot does not start an image extension (``ceil.blend``) gets one appended, as the engine
    does (``ceil.blend.png``); it was read as ``ceil`` + extension ``.blend``, and the plain ``ceil.png``
    beside it taken first. A name with an image extension the engine reads (``.bmp``) is taken as it is."""
    bmp = io.BytesIO()
    Image.new("RGB", (4, 4), (10, 20, 30)).save(bmp, format="BMP")
    textures = [("textures/test/ceil.blend", 0, 1), ("textures/test/pic.bmp", 0, 1)]
    extra = {"textures/test/ceil.png": _png(WALL_RGB), "textures/test/ceil.blend.png": _png(SKY_RGB),
             "textures/test/pic.bmp": bmp.getvalue()}
    blend, pic = convert_bsp(_pk3(tmp_path / "dots.pk3", textures, extra=extra)).scene.materials
    assert blend.texture is not None and tuple(blend.texture[0, 0, :3]) == SKY_RGB
    assert pic.texture is not None and tuple(pic.texture[0, 0, :3]) == (10, 20, 30)


# -- malformed files ------------------------------------------------------------------------------------

def _set_lump(data: bytes, lump: int, offset: int | None = None, length: int | None = None) -> bytes:
    """``data`` with lump ``lump``'s directory entry changed."""
    off, ln = struct.unpack_from("<ii", data, 8 + 8 * lump)
    out = bytearray(data)
    struct.pack_into("<ii", out, 8 + 8 * lump, off if offset is None else offset, ln if length is None else length)
    return bytes(out)


def _set_face(data: bytes, face: int, **fields: int) -> bytes:
    """``data`` with fields of face ``face`` changed."""
    off, ln = struct.unpack_from("<ii", data, 8 + 8 * 13)
    faces = np.frombuffer(data, FACE_DT, count=ln // FACE_DT.itemsize, offset=off).copy()
    for k, v in fields.items():
        faces[face][k] = v
    return data[:off] + faces.tobytes() + data[off + ln:]


TWO_WALLS = [("textures/test/wall", 0, 1), ("textures/test/lava_1", 0, 1)]


@pytest.mark.parametrize(("damage", "message"), [
    (lambda d: d[:100], "too short for a BSP header"),
    (lambda d: _set_lump(d, 13, length=1 << 20), r"lump 13 \(offset \d+, length 1048576\) runs past the file end"),
    (lambda d: _set_lump(d, 13, offset=-4), r"lump 13 \(offset -4, .*\) runs past the file end"),
    (lambda d: _set_lump(d, 1, length=71), "texture lump length 71 is not a multiple of 72"),
    (lambda d: _set_lump(d, 10, length=43), "vertex lump length 43 is not a multiple of 44"),
    (lambda d: _set_face(d, 1, texture=5), "a face refers to texture 5 of 2"),
    (lambda d: _set_face(d, 1, texture=-1), "a face refers to texture -1 of 2"),
    (lambda d: _set_face(d, 1, n_vertexes=99), r"faces index past the vertex \(103/8\)"),
    (lambda d: _set_face(d, 0, n_meshverts=60), r"meshvert \(60/12\) lumps"),
    (lambda d: _set_face(d, 1, n_meshverts=-3), "negative vertex or meshvert offset or count"),
    (lambda d: _set_face(d, 1, meshvert=-6), "negative vertex or meshvert offset or count"),
    (lambda d: _set_face(d, 1, vertex=-4), "negative vertex or meshvert offset or count"),
])
def test_malformed_bsp_raises_scene_format_error(tmp_path: Path, damage, message: str) -> None:
    """A truncated or inconsistent BSP raises SceneFormatError naming the problem (never an IndexError,
    a numpy error or a map silently built from the wrong vertices)."""
    path = tmp_path / "bad.bsp"
    path.write_bytes(damage(_map(TWO_WALLS, SPAWN)))
    with pytest.raises(SceneFormatError, match=message):
        convert_bsp(path)


def test_unusable_sources_raise_typed_errors(tmp_path: Path) -> None:
    """Only .bsp and .pk3 files are converted, and a pk3 without exactly one map needs ``map_name``."""
    other = tmp_path / "m.zip"
    other.write_bytes(_map(TWO_WALLS, SPAWN))
    with pytest.raises(SceneFormatError, match=r"expected a \.bsp or \.pk3 file"):
        convert_bsp(other)
    two = tmp_path / "two.pk3"
    with zipfile.ZipFile(two, "w") as z:
        z.writestr("maps/a.bsp", _map(TWO_WALLS, SPAWN))
        z.writestr("maps/b.bsp", _map(TWO_WALLS, SPAWN))
    with pytest.raises(SceneFormatError, match=r"holds 2 maps \(\['maps/a.bsp', 'maps/b.bsp'\]\); pass map_name"):
        convert_bsp(two)
    assert convert_bsp(two, "b").scene.name == "b"
    none = tmp_path / "none.pk3"
    with zipfile.ZipFile(none, "w") as z:
        z.writestr("textures/test/wall.png", _png(WALL_RGB))
    with pytest.raises(SceneFormatError, match="holds 0 maps"):
        convert_bsp(none)


def test_damaged_pk3_members(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """A damaged shader script is skipped with a warning (the map converts without its shaders); a
    damaged map or texture raises SceneFormatError naming the member, not zipfile.BadZipFile."""
    textures = [("textures/test/wall", 0, 1), ("textures/test/fence", 0, 1)]
    path = _pk3(tmp_path / "shader.pk3", textures)
    damage_zip_member(path, "scripts/test.shader")
    with caplog.at_level("WARNING", logger="rtp"):
        conv = convert_bsp(path)
    assert any("skipping shader script scripts/test.shader" in r.getMessage() for r in caplog.records)
    fence = conv.scene.materials[1]
    assert fence.alpha_cutoff is None and (fence.texture[..., 3] == 255).all()  # its alphaFunc was not read
    for member in ("maps/m.bsp", "textures/test/wall.png"):
        path = _pk3(tmp_path / f"{member.replace('/', '_')}.pk3", textures)
        damage_zip_member(path, member)
        with pytest.raises(SceneFormatError, match=rf"{member} in .* is damaged \(Bad CRC-32.*\): replace the archive"):
            convert_bsp(path)


def _set_member_header(archive: Path, member: str, *, method: int | None = None, flags: int | None = None) -> None:
    """Member ``member`` of ``archive`` marked (in its local and central headers) with compression ``method``
    or general-purpose ``flags``, its data unchanged."""
    with zipfile.ZipFile(archive) as z:
        offset = z.getinfo(member).header_offset
    data = bytearray(archive.read_bytes())
    central = data.rindex(b"PK\x01\x02")  # (the central header of the archive's only member)
    for at, rel in ((offset, 0), (central, 2)):  # local: flags at 6, method at 8; central: at 8 and 10
        if flags is not None:
            struct.pack_into("<H", data, at + 6 + rel, flags)
        if method is not None:
            struct.pack_into("<H", data, at + 8 + rel, method)
    archive.write_bytes(bytes(data))


@pytest.mark.parametrize(("change", "why"), [
    ({"method": 9}, "compression method is not supported"),  # Deflate64 (7-Zip, Windows)
    ({"flags": 1}, "encrypted"),
])
def test_a_pk3_member_zipfile_cannot_read_is_a_scene_format_error(tmp_path: Path, change: dict, why: str) -> None:
    """A map stored with a compression method zipfile lacks, or encrypted, raised zipfile's bare
    NotImplementedError or RuntimeError: now a SceneFormatError naming the member and saying to repack."""
    path = tmp_path / "packed.pk3"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("maps/m.bsp", _map([("textures/test/wall", 0, 1)], SPAWN))
    _set_member_header(path, "maps/m.bsp", **change)
    with pytest.raises(SceneFormatError, match=rf"maps/m\.bsp in .*packed\.pk3 cannot be read \(.*{why}.*\): .*repack"):
        convert_bsp(path)


def _set_vertices(data: bytes, **fields: object) -> bytes:
    """``data`` with fields of every vertex changed."""
    off, ln = struct.unpack_from("<ii", data, 8 + 8 * 10)
    verts = np.frombuffer(data, VERTEX_DT, count=ln // VERTEX_DT.itemsize, offset=off).copy()
    for k, v in fields.items():
        verts[k] = v
    return data[:off] + verts.tobytes() + data[off + ln:]


def test_a_map_whose_values_make_no_scene_names_its_file(tmp_path: Path) -> None:
    """NaN vertices raised the scene model's ``Mesh.positions: expected finite values`` (an
    sdk.ParameterError naming neither the map nor the file): now a SceneFormatError naming the file (the
    map inside its pk3), with the model's words."""
    path = tmp_path / "nan.bsp"
    path.write_bytes(_set_vertices(_map(TWO_WALLS, SPAWN), pos=np.nan))
    with pytest.raises(SceneFormatError, match=r"nan\.bsp: its data makes no valid scene \(Mesh\.positions: "
                                               r"expected finite values"):
        convert_bsp(path)
    pk3 = tmp_path / "nan.pk3"
    with zipfile.ZipFile(pk3, "w") as z:
        z.writestr("maps/m.bsp", path.read_bytes())
    with pytest.raises(SceneFormatError, match=r"maps/m\.bsp in .*nan\.pk3: its data makes no valid scene"):
        convert_bsp(pk3)


@pytest.mark.parametrize(("kwargs", "message"), [
    # 0 and -1 silently dropped every curved surface, -3 was numpy's ValueError, 2.5 a TypeError, 10**6 a MemoryError
    ({"patch_level": 0}, r"patch_level: expected an integer from 1 to 64, got 0"),
    ({"patch_level": -1}, r"patch_level: expected an integer from 1 to 64, got -1"),
    ({"patch_level": -3}, r"patch_level: expected an integer from 1 to 64, got -3"),
    ({"patch_level": 2.5}, r"patch_level: expected an integer from 1 to 64, got 2\.5"),
    ({"patch_level": 10**6}, r"patch_level: expected an integer from 1 to 64, got 1000000"),
    ({"patch_level": True}, r"patch_level: expected an integer"),
    # -1 kept all lights but the weakest (the slice [:-1])
    ({"max_point_lights": -1}, r"max_point_lights: expected an integer from 0 to 256, got -1"),
    ({"max_point_lights": 1.5}, r"max_point_lights: expected an integer from 0 to 256, got 1\.5"),
    ({"max_point_lights": 10**6}, r"max_point_lights: expected an integer from 0 to 256, got 1000000"),
    ({"eye_height_units": float("nan")}, r"eye_height_units: expected a finite number of Q3 units from -65536"),
    ({"eye_height_units": 10**400}, r"eye_height_units: expected a finite number"),
])
def test_conversion_options_out_of_range_are_parameter_errors(tmp_path: Path, kwargs: dict, message: str) -> None:
    from rtp.capture.scenes import load_bsp
    from rtp.sdk import ParameterError

    path = tmp_path / "m.bsp"
    path.write_bytes(_map(TWO_WALLS, SPAWN))
    with pytest.raises(ParameterError, match=message) as e:
        convert_bsp(path, **kwargs)
    assert e.value.name == next(iter(kwargs))
    with pytest.raises(ParameterError, match=message):
        load_bsp(path, **kwargs)


def test_conversion_options_at_their_bounds(tmp_path: Path) -> None:
    """patch_level 1 tessellates a 3x3 block into 2 triangles; max_point_lights 0 keeps no light."""
    c = (0.0, 0.0, 1.0)
    patch = [((x, y, 0.0), (x / 64, y / 64), c) for y in (0, 32, 64) for x in (0, 32, 64)]
    path = tmp_path / "p.bsp"
    path.write_bytes(_faces_map([("textures/test/wall", 0, 1)], [(2, 0, patch, [], (3, 3))], SPAWN))
    assert convert_bsp(path, patch_level=1).scene.triangle_count == 2
    assert convert_bsp(path, patch_level=64).scene.triangle_count == 2 * 64 * 64
    assert convert_bsp(path, max_point_lights=0).scene.point_lights == []
