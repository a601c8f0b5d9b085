"""The BSP conversion rules of docs/scenes.md that the tiny map of test_scenes.py does not reach:
dropped surfaces, alpha tests, emission, the light fallbacks (entities, surface lights, light-looking
textures, lights above the spawns), the sun and the sky colour. Each case is a synthetic map."""

from __future__ import annotations

import io
import math
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rtp.capture.scenes import convert_bsp
from rtp.capture.scenes._bsp import FACE_DT, TEXTURE_DT, UNIT, VERTEX_DT
from rtp.scene import Scene
from rtp.sdk import srgb_to_linear

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
    tex = np.zeros(len(textures), TEXTURE_DT)
    tex["name"] = [t[0].encode() for t in textures]
    tex["flags"] = [t[1] for t in textures]
    tex["contents"] = [t[2] for t in textures]
    verts: list = []
    meshverts: list[int] = []
    faces = np.zeros(len(textures), FACE_DT)
    for i in range(len(textures)):
        vs, mv = _quad(100.0 * i, 0.0, 64.0, 128.0, up=False)
        faces[i]["texture"], faces[i]["type"], faces[i]["vertex"], faces[i]["n_vertexes"] = i, 1, len(verts), 4
        faces[i]["meshvert"], faces[i]["n_meshverts"] = len(meshverts), 6
        verts += vs
        meshverts += mv
    varr = np.zeros(len(verts), VERTEX_DT)
    for i, (p, uv, n) in enumerate(verts):
        varr[i]["pos"], varr[i]["uv"], varr[i]["normal"], varr[i]["color"] = p, uv, n, (255, 255, 255, 255)
    lumps = [b""] * 17
    lumps[0], lumps[1], lumps[10] = entities.encode() + b"\0", tex.tobytes(), varr.tobytes()
    lumps[11], lumps[13] = np.asarray(meshverts, "<i4").tobytes(), faces.tobytes()
    body, directory = b"", []
    for lump in lumps:
        directory.append((8 + 17 * 8 + len(body), len(lump)))
        body += lump + b"\0" * (-len(lump) % 4)
    return b"IBSP" + struct.pack("<i", 46) + b"".join(struct.pack("<ii", *d) for d in directory) + body


SPAWN = '{\n"classname" "info_player_deathmatch"\n"origin" "32 16 8"\n"angle" "90"\n}\n'


def _pk3(path: Path, textures: list[tuple[str, int, int]], entities: str = SPAWN, shaders: str = SHADERS) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("maps/m.bsp", _map(textures, entities))
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
