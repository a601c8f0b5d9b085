"""Rate orientation end to end: ``WxH`` is W pixels wide by H tall (design.md), and every part of rtp agrees.

One mixed-up axis anywhere would make a method pick the wrong anisotropic rate without a visible error. The
frames here have a known answer: a camera-facing quad textured with stripes that vary along one screen axis only.
With vertical stripes (varying along x, constant along y) shading at 1x2 (1 wide, 2 tall) loses nothing and 2x1
loses a lot; with horizontal stripes the other way round. Each component must say so: the reference renderer's
software VRS and the dataset's composite, the targets, the SDK's codes and selection, the extrapolation, the GPU
RateSelector, the overlay, Yang 2019's and FidelityFX's decisions, the engine's motion-blur rates, the transposing
augmentation, the planes of differences and block variances, examples/runtime_without_rtp.py, and the shipped
models (trained on data whose orientation all of the above fixed).
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import metrics, sdk
from rtp.capture.paths import composite
from rtp.evaluate import FidelityFX, Yang2019, motion_rates
from rtp.evaluate._evaluate import CONTAINED_RATES
from rtp.evaluate.plots import rate_legend
from rtp.plugins.moderngl import RateSelector, Renderer
from rtp.scene import Camera, Material, Scene, SunLight, quad_mesh
from rtp.train._augment import SYMMETRIES, augment_sample
from tests.conftest import base_metadata, make_current

W, H, TILE = 96, 64, 16
#: the stripes' orientation -> (the rate that loses nothing, its transposed twin that loses the most of the two)
CHEAP = {"vertical": ("1x2", "2x1"), "horizontal": ("2x1", "1x2")}
SWAP = {"1x2": "2x1", "2x1": "1x2", "2x4": "4x2", "4x2": "2x4"}
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "runtime_without_rtp.py"


def _stripes_scene(orientation: str) -> Scene:
    """A quad filling the view, 1-texel stripes of dark and light (about 2 pixels each on screen), lit by the
    ambient light alone (no sun, no specular): the image varies along one axis only."""
    tex = np.full((64, 64, 4), 255, np.uint8)
    if orientation == "vertical":  # columns alternate: the image varies along x only
        tex[:, 1::2, :3] = 30
    else:  # rows alternate: along y only
        tex[1::2, :, :3] = 30
    material = Material("stripes", texture=tex, specular=0.0, roughness=1.0)
    return Scene("stripes", [quad_mesh((0, 0, -5), (8, 0, 0), (0, 6, 0), 0)], [material],
                 sun=SunLight(intensity=0.0), ambient=0.8)


@pytest.fixture(scope="module", params=sorted(CHEAP))
def stripes(request: pytest.FixtureRequest, gl_context: Any) -> dict[str, Any]:
    """The stripes rendered twice from one camera (the second reprojects the first), FXAA off, with the true
    JNYang targets of every rate."""
    orientation = request.param
    with Renderer(W, H, ctx=make_current(gl_context), shadow_map_size=256, fxaa=False) as r:
        r.load_scene(_stripes_scene(orientation))
        cam = Camera((0.0, 0.0, 0.0))
        prev = r.render(cam)
        cur = r.render(cam, prev)
        ref = cur.colour["1x1"]
        truth = metrics.tile_targets(ref, {q: cur.colour[q] for q in sdk.PREDICTED_RATES}, ("jnyang",), TILE)["jnyang"]
        cheap, dear = CHEAP[orientation]
        codes = np.full(sdk.tile_grid(H, W, TILE), sdk.RATE_CODES[cheap], np.uint8)
        shaded = {q: r.shade_rates(np.full(codes.shape, sdk.RATE_CODES[q], np.uint8), TILE) for q in (cheap, dear)}
    return {"orientation": orientation, "cheap": cheap, "dear": dear, "frame": cur, "truth": truth, "codes": codes,
            "shaded": shaded}


def _index(rate: str) -> int:
    return sdk.PREDICTED_RATES.index(rate)


# ----------------------------------------------------------------------------- the convention itself
def test_names_sizes_and_codes_agree_with_design_md() -> None:
    assert sdk.RATE_CODES == {"1x1": 0, "1x2": 1, "2x1": 4, "2x2": 5, "2x4": 6, "4x2": 9, "4x4": 10}
    for name, code in sdk.RATE_CODES.items():
        w, h = sdk.rate_size(name)
        assert name == f"{w}x{h}" and code == (int(math.log2(w)) << 2) | int(math.log2(h))
        assert sdk.RATE_NAMES[code] == name
    # a 1x2 block is contained by 2x2 and 2x4 (no wider, no taller), never by 4x2's twin 2x1 the other way
    assert [sdk.PREDICTED_RATES[j] for j in CONTAINED_RATES[_index("2x4")]] == ["1x2", "2x1", "2x2"]


# ----------------------------------------------------------------------------- the renderer and the truth
@pytest.mark.gl
def test_software_vrs_and_composite_lose_nothing_along_the_constant_axis(stripes: dict[str, Any]) -> None:
    f, cheap, dear = stripes["frame"], stripes["cheap"], stripes["dear"]
    ref = f.colour["1x1"]
    along = 0 if stripes["orientation"] == "vertical" else 1  # the axis the image is constant along
    assert np.abs(np.diff(ref, axis=along)).max() == 0.0 and np.abs(np.diff(ref, axis=1 - along)).max() > 0.3
    assert np.array_equal(f.colour[cheap], ref)
    assert np.abs(f.colour[dear] - ref).mean() > 0.05
    # the per-tile VRS of a rate image of codes, and the dataset's composite of it, are the rate's image
    assert np.array_equal(stripes["shaded"][cheap], ref)
    assert np.array_equal(stripes["shaded"][dear], f.colour[dear])
    assert np.array_equal(composite(f.colour, stripes["codes"], TILE), ref)


@pytest.mark.gl
def test_targets_are_zero_for_the_rate_along_the_stripes(stripes: dict[str, Any]) -> None:
    truth, cheap, dear = stripes["truth"], stripes["cheap"], stripes["dear"]
    assert truth[_index(cheap)].max() == 0.0
    assert truth[_index(dear)].min() > 0.3
    # the quarter rates: the one coarse along the stripes only doubles the dear half rate's loss less than its twin
    tall = "2x4" if cheap == "1x2" else "4x2"
    assert np.all(truth[_index(tall)] < truth[_index(SWAP[tall])])


# ----------------------------------------------------------------------------- the SDK
@pytest.mark.gl
def test_sdk_selects_the_code_of_the_rate_along_the_stripes(stripes: dict[str, Any]) -> None:
    truth, cheap = stripes["truth"], stripes["cheap"]
    codes = sdk.select_rates(truth, 0.2)
    assert np.all(codes == sdk.RATE_CODES[cheap]) and np.array_equal(codes, stripes["codes"])
    assert sdk.rate_size(sdk.RATE_NAMES[int(codes[0, 0])]) == tuple(int(v) for v in cheap.split("x"))
    # the budget's: half the work saved is the cheap half rate everywhere
    chosen = sdk.select_rates_for_saving(truth, 0.5)
    assert np.all(chosen.rates == sdk.RATE_CODES[cheap]) and chosen.saved == 0.5


@pytest.mark.gl
def test_extrapolation_follows_the_axis(stripes: dict[str, Any]) -> None:
    truth, cheap, dear = stripes["truth"], stripes["cheap"], stripes["dear"]
    k = sdk.DEFAULT_EXTRAPOLATION_K
    e = {r: truth[_index(r)].astype(np.float64) for r in ("1x2", "2x1")}
    full = sdk.extrapolate(np.stack([e["1x2"], e["2x1"]]), ("1x2", "2x1"), k)
    e22 = np.maximum(e["1x2"], e["2x1"])
    # docs/runtime.md: 2x4 = max(k e12, e22), 4x2 = max(k e21, e22)
    np.testing.assert_allclose(full[_index("2x4")], np.maximum(k * e["1x2"], e22))
    np.testing.assert_allclose(full[_index("4x2")], np.maximum(k * e["2x1"], e22))
    tall = "2x4" if cheap == "1x2" else "4x2"  # coarse along the stripes: only the 2x2 loss
    np.testing.assert_allclose(full[_index(tall)], e[dear])
    assert np.all(full[_index(SWAP[tall])] > full[_index(tall)])


@pytest.mark.gl
def test_gpu_rate_selector_and_the_example_port_pick_the_same_rate(stripes: dict[str, Any], gl_context: Any) -> None:
    truth, cheap = stripes["truth"], stripes["cheap"]
    # a model whose network output is the true error of 1x2 and 2x1 (clamped transform, mu_y 0.5: identity)
    meta_d = base_metadata(transform={"type": "clamped", "mu_y": 0.5}, outputs=["1x2", "2x1"])
    meta = sdk.ModelMetadata.from_dict(meta_d)
    raw = truth[[_index("1x2"), _index("2x1")]].astype(np.float32)
    want = sdk.select_rates(meta.decode(raw), 0.2)
    assert np.all(want == sdk.RATE_CODES[cheap])
    with RateSelector(meta, make_current(gl_context)) as selector:
        assert np.array_equal(selector.select(raw, 0.2), want)
        # the budget's shader: half the work saved is the cheap half rate
        assert np.all(selector.select(raw, saving=0.5) == sdk.RATE_CODES[cheap])
        # beside an engine's rates (combine.glsl): max with the cheap rate keeps it, with its twin shades 2x2
        for engine, combiner in ((cheap, "max"), (SWAP[cheap], "max"), (SWAP[cheap], "min"), (cheap, "sum")):
            cpu = sdk.select_rates(meta.decode(raw), 0.2, engine_rates=engine, combiner=combiner)
            gpu = selector.select(raw, 0.2, engine_rates=sdk.RATE_CODES[engine], combiner=combiner)
            assert np.array_equal(gpu, cpu), (engine, combiner)
        assert np.all(sdk.select_rates(meta.decode(raw), 0.2, engine_rates=cheap, combiner="max")
                      == sdk.RATE_CODES[cheap])
        assert sdk.combine_rates(cheap, SWAP[cheap], "max") == sdk.RATE_CODES["2x2"]
        assert sdk.combine_rates(cheap, cheap, "sum") == sdk.RATE_CODES[cheap]  # (1x4 or 4x1: clamped back)
    spec = importlib.util.spec_from_file_location("runtime_without_rtp_orientation", EXAMPLE)
    assert spec is not None and spec.loader is not None
    port = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(port)
    assert port.CODES == sdk.RATE_CODES and port.RATES == sdk.PREDICTED_RATES
    assert np.array_equal(port.select(port.decode(raw, meta_d), meta_d, 0.2), want)


@pytest.mark.gl
def test_overlay_draws_the_chosen_rate_in_its_class(stripes: dict[str, Any]) -> None:
    ref, codes = stripes["frame"].colour["1x1"], stripes["codes"]
    grey = np.full_like(ref, 0.5)
    drawn = sdk.draw_rate_overlay(grey, codes, TILE, alpha=1.0, grid=False)
    assert np.allclose(drawn, np.asarray(sdk.OVERLAY_COLOURS["fine"], np.float32))  # a half rate: fine
    legend = dict(rate_legend())
    fine = next(label for label in legend if label.startswith("fine"))
    assert stripes["cheap"] in fine and legend[fine] == sdk.OVERLAY_COLOURS["fine"]


# ----------------------------------------------------------------------------- the baselines and engine rates
@pytest.mark.parametrize("orientation", sorted(CHEAP))
def test_yang_2019_and_fidelityfx_coarsen_along_the_stripes(orientation: str) -> None:
    """On 1-pixel stripes (every 2x2 coarse pixel alike, so FidelityFX's anti-burn-in term, which adds the
    neighbours' luma range to every axis, is 0; wider stripes get 1x1 from it, as from FFX's own shader)."""
    cheap, dear = CHEAP[orientation]
    image = np.full((H, W, 3), 0.2, np.float32)
    if orientation == "vertical":
        image[:, 1::2] = 0.8
    else:
        image[1::2] = 0.8
    source = {"reprojected": image, "motion": np.zeros((H, W, 2), np.float32), "seen": np.ones((H, W), np.float32)}
    code = sdk.RATE_CODES[cheap]
    yang = Yang2019(TILE)
    est = yang.predict(source)
    assert est[_index(cheap)].max() == 0.0 and est[_index(dear)].min() > 0.3
    assert np.all(yang.shading_rates(source) == code)
    tall = "2x4" if cheap == "1x2" else "4x2"  # NAS without 4x4: the axis with the larger error stays finer
    assert np.all(Yang2019(TILE, allow_4x4=False).shading_rates(source, threshold=100.0) == sdk.RATE_CODES[tall])
    for additional in (False, True):
        ffx = FidelityFX(TILE, additional_rates=additional)
        assert np.all(ffx.shading_rates(source) == code), additional
        deltas = ffx.predict(source)
        assert deltas[_index(cheap)].max() == 0.0 and deltas[_index(dear)].min() > 0.3, additional


def test_motion_blur_rates_coarsen_along_the_motion() -> None:
    zero, fast = np.zeros((32, 32)), np.full((32, 32), 3.0)
    assert np.all(motion_rates(fast, zero, 16) == sdk.RATE_CODES["2x1"])  # moving along x: coarse in x
    assert np.all(motion_rates(zero, fast, 16) == sdk.RATE_CODES["1x2"])


# ----------------------------------------------------------------------------- inputs and training
@pytest.mark.gl
def test_difference_and_block_planes_see_the_stripes_on_their_axis(stripes: dict[str, Any]) -> None:
    f, cheap = stripes["frame"], stripes["cheap"]
    dx, dy = (f.channel(f"reprojected.y.{d}") for d in ("dx", "dy"))
    along, across = (dy, dx) if cheap == "1x2" else (dx, dy)
    assert along.max() == 0.0 and across.mean() > 0.1
    blocks = f.channel("reprojected.y.blocks")
    # the values of rate k on pixel k of each 4x4 cell, in sdk.BLOCK_RATES order
    values = {r: blocks[k // 4::4, k % 4::4] for k, r in enumerate(sdk.BLOCK_RATES)}
    assert values[cheap].max() == 0.0 and values[SWAP[cheap]].mean() > 0.5


@pytest.mark.gl
def test_transposing_augmentation_swaps_the_targets_as_the_image_turns(stripes: dict[str, Any]) -> None:
    """A transposed crop's targets must be the targets the transposed images have (computed afresh)."""
    f, truth, cheap = stripes["frame"], stripes["truth"], stripes["cheap"]
    side = H  # a square crop of whole tiles at the top-left corner
    inputs = ("reprojected.y", "seen", "albedo.y", "normal.z")
    x = np.stack([f.channel(c)[:side, :side] for c in inputs]).astype(np.float32)
    y = truth[:, : side // TILE, : side // TILE]
    transpose = SYMMETRIES.index((True, False, False))
    xt, yt = augment_sample(x, y, inputs, sdk.PREDICTED_RATES, transpose)
    np.testing.assert_array_equal(xt[0], x[0].T)

    def turned(image: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(image[:side, :side].transpose(1, 0, 2))

    # the transposed frame shaded at rate r is the frame shaded at its twin, transposed (block samples at centres)
    fresh = metrics.tile_targets(turned(f.colour["1x1"]),
                                 {r: turned(f.colour[SWAP.get(r, r)]) for r in sdk.PREDICTED_RATES}, ("jnyang",),
                                 TILE)["jnyang"]
    np.testing.assert_allclose(yt, fresh, rtol=1e-5, atol=1e-6)
    assert yt[_index(SWAP[cheap])].max() == 0.0 and yt[_index(cheap)].min() > 0.3


@pytest.mark.gl
def test_every_shipped_model_predicts_the_rate_along_the_stripes_cheaper(stripes: dict[str, Any]) -> None:
    """Trained on targets, crops and augmentations whose orientation the tests above fix, every shipped model
    predicts the rate along the stripes to lose less than its transposed twin, on average over the frame."""
    f, cheap, dear = stripes["frame"], stripes["cheap"], stripes["dear"]
    tall = "2x4" if cheap == "1x2" else "4x2"
    for name in sdk.shipped_models():
        pred = sdk.load(name)
        values = pred.predict(np.stack([f.channel(c) for c in pred.metadata.inputs])).astype(np.float64)
        mean = values.reshape(6, -1).mean(axis=1)
        sign = -1.0 if pred.metadata.higher_is_better else 1.0  # (PSNR: the cheaper loss is the higher dB)
        assert sign * mean[_index(cheap)] < sign * mean[_index(dear)], (name, mean.round(3).tolist())
        assert sign * mean[_index(tall)] < sign * mean[_index(SWAP[tall])], (name, mean.round(3).tolist())
