"""The runtime contract in one file, without rtp: what an engine in C++ (or any language) ports.

    python examples/runtime_without_rtp.py models/jnyang.onnx                    # a random 1280x720 frame
    python examples/runtime_without_rtp.py MODEL.onnx --frame planes.npy --threshold 0.2 --tile-size 8
    python examples/runtime_without_rtp.py models/flip.onnx --check              # the same rates as rtp.sdk?
    python examples/runtime_without_rtp.py models/jnyang.onnx --saving 0.6 --check   # a budget (step 7)
    python examples/runtime_without_rtp.py models/jnyang.onnx --engine-rate 2x1 --check   # beside it (step 8)
    python examples/runtime_without_rtp.py models/jnyang.onnx --engine-rate 2x2 --saving 0.8 --check   # both

An engine that links onnxruntime itself (C++, C#, Rust) needs no Python: the ONNX file carries the
network and its metadata, and the steps from the engine's input planes to a shading-rate image are
the ones below, each a few lines. This file uses nothing but ``json``, numpy and onnxruntime (the
same calls exist in onnxruntime's C and C++ API: ``LookupCustomMetadataMap``, ``GetInputTypeInfo``,
``Run``), so each step reads as what to port. ``--check`` then loads the same model with
``rtp.sdk`` and compares the two: the shading-rate codes must be the same on every tile
(tests/test_runtime_without_rtp.py compares the two on every shipped model).

1. **Metadata** (docs/metadata.md): one JSON object under the model's ``metadata_props`` key
   ``rtp.metadata``; the fields used here are ``inputs`` (plane names, in the order the network
   reads them), ``outputs`` (the rates the network predicts), ``tile_size``, ``input_multiple``,
   ``transform``, ``safety``, ``higher_is_better``, ``extrapolation_k``, ``default_threshold``,
   ``rate_factors`` and ``finite_probe``.
2. **Padding** (docs/runtime.md "predictor.predict(x)", step 2): the frame's bottom rows and right
   columns repeated up to ``input_multiple`` (whole tiles when there is none; a model with a fixed
   input size up to that size). A model that reads ``.blocks`` planes wants a width that is a multiple
   of 4 and a height other than 4k + 1; one that reads ``.tiles`` planes W mod 16 outside 1-3 and H mod 16
   outside 1-2: those planes pack each cell's values on its first rows and columns, and a frame that
   cuts a cell loses them (the network reads padding copies instead). As ``predict``, the port logs a
   warning once per frame size where that happens (``cut_planes``); the rates are still given.
3. **Inference**: the planes go to the graph's inputs in graph order, each input taking as many
   consecutive planes as its channel dimension (rtp-export splits eight or more planes into groups of
   at most seven: docs/export.md "Input planes in groups"). The output that is not the finite probe
   (and not ``features``, a splitting network's trunk) holds the network's per-tile values.
4. **Decode** (docs/metadata.md "Transforms"): the safety margin added in the direction that makes
   the image worse, the inverse transform to metric units, then the missing rates extrapolated
   (docs/runtime.md "Extrapolation"): six values per tile, ``1x2, 2x1, 2x2, 2x4, 4x2, 4x4``.
5. **Hardware tiles**, where the GPU's shading-rate tile differs from the model's: coarser, each
   hardware tile takes the worst of the model tiles it covers; finer, each takes its model tile's.
6. **Selection** (docs/runtime.md "predictor.shading_rates(x, threshold=None, allowed=None)"): per
   tile the cheapest allowed rate whose value passes its threshold (``threshold x rate_factors[r]``;
   PSNR ``threshold - 20 log10 rate_factors[r]`` dB), equal-cost rates compared by value over their
   own threshold; else 1x1. The result is D3D12/Vulkan rate codes, ready to upload as the
   shading-rate image.
7. **A budget** instead of a threshold (docs/runtime.md "A budget: a share of the work saved instead of
   a threshold"), where the engine holds the work rather than the quality: the lowest threshold whose
   step-6 rates save a share of the frame's shading work. A tile's saving grows with the threshold one
   step a cost class, so the frame's saving is a sum of steps; sorted (``std::sort``, or
   ``std::nth_element`` rounds as rtp.sdk does), the step where their weighted sum reaches the share
   gives the threshold, and step 6 the rates.

8. **Beside the engine's own rates** (docs/runtime.md "The engine's own rates: the hardware's
   combiners"), where the engine writes rates too (foveation, motion blur, a per-draw rate) and the
   hardware's combiner (``min``, ``max``: per axis; ``sum``: the sizes multiplied) meets them with the
   image: per tile each candidate rate's combination with the engine's, clamped to a rate the device has
   (Vulkan's rule), judged by its value (the worse of two where a device may choose), the cheapest
   passing kept, else the engine's rate alone.

   With a budget too (step 7 beside step 8): what the engine's rates save alone is counted first, and each
   candidate's step is that of the rate the device shades for it, adding only what the engine's rates do not
   save already.

The ranges the SDK takes, which the command line checks as it does (``ParameterError`` there): a
threshold finite, in [0, 1e6] for an error metric and [-1e6, 1e6] dB for PSNR; a saving in [0, 1 - 1/area]
of the coarsest allowed rate (0.9375 with 4x4, 0 with none: a budget past what the allowed rates save
cannot be reached); an engine's rate 1x1 or one of the allowed rates (a device shades a rate of its own
choice for another).

What is left out: checking the frame for NaN (the finite probe makes that one scalar: step 3's
other output; the command line checks a ``--frame`` on the CPU), batches of frames, and reusing a
prediction across frames (``sdk.PredictionReuse``, docs/runtime.md).
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from pathlib import Path

import numpy as np
import onnxruntime as ort

#: The six reduced rates in the order of the decoded values, and their D3D12 / Vulkan codes
#: ((log2 width) << 2 | log2 height; docs/runtime.md): 1x1 is 0.
RATES = ("1x2", "2x1", "2x2", "2x4", "4x2", "4x4")
CODES = {"1x1": 0, "1x2": 1, "2x1": 4, "2x2": 5, "2x4": 6, "4x2": 9, "4x4": 10}
#: Where the logistic transform's inverse clips its sigmoid (docs/metadata.md "Transforms").
LOGIT_EPS = 1e-7
#: The largest threshold magnitude the SDK takes (``sdk.MAX_THRESHOLD``).
MAX_THRESHOLD = 1e6

log = logging.getLogger("runtime_without_rtp")
_WARNED_CUTS: set[tuple[tuple[str, ...], int, int]] = set()  # (the cut planes, H, W) already warned of


def read_metadata(session: ort.InferenceSession) -> dict:
    """Step 1: the model's rtp metadata, a JSON object."""
    text = session.get_modelmeta().custom_metadata_map.get("rtp.metadata")
    if text is None:
        raise ValueError("the model carries no rtp.metadata: export it with rtp-export, or adopt it with a sidecar")
    return json.loads(text)


def fixed_size(session: ort.InferenceSession) -> tuple[int, int] | None:
    """(H, W) of a model with a fixed input size, else None (its height or width free)."""
    fixed = session.get_inputs()[0].shape[2:]
    return (fixed[0], fixed[1]) if all(isinstance(d, int) and d > 0 for d in fixed) else None


def cut_planes(meta: dict, h: int, w: int) -> list[str]:
    """Step 2's check: the model's ``.blocks`` and ``.tiles`` planes whose last cells a ``h x w`` frame cuts.
    ``.blocks`` packs each 4x4 cell's six values on its first two rows, four columns (a width not a multiple of
    4, or a height of 4k + 1, loses some); ``.tiles`` each 16-pixel tile's twelve on its first three rows, four
    columns (W mod 16 of 1-3, H mod 16 of 1-2)."""
    return [c for c in meta["inputs"] if (c.endswith(".blocks") and (w % 4 or h % 4 == 1))
            or (c.endswith(".tiles") and (w % 16 in (1, 2, 3) or h % 16 in (1, 2)))]


def pad(x: np.ndarray, meta: dict, session: ort.InferenceSession) -> np.ndarray:
    """Step 2: (C, H, W) padded at the bottom and right by repeating the last row and column (a warning, once per
    frame size, where the frame cuts the cells of its packed planes)."""
    _, h, w = x.shape
    cut = cut_planes(meta, h, w)
    if cut and (tuple(cut), h, w) not in _WARNED_CUTS:
        _WARNED_CUTS.add((tuple(cut), h, w))
        log.warning("a %dx%d frame cuts the last cells of its %s planes: the values they pack on pixels past the "
                    "frame's edge are lost, the network reads copies of the frame's last column or row in their "
                    "place, and predicts the last tile column or row (and the tiles beside it) from wrong inputs; "
                    "render at a size whose sides are multiples of 4", w, h, ", ".join(cut))
    fixed = fixed_size(session)
    if fixed is not None:  # a model with a fixed input size: a larger frame does not fit
        ph, pw = fixed
        if h > ph or w > pw:
            raise ValueError(f"the model has a fixed input of {pw}x{ph}; a {w}x{h} frame does not fit (smaller "
                             f"frames are padded up to it)")
    else:
        m = meta.get("input_multiple") or meta["tile_size"]
        ph, pw = -(-h // m) * m, -(-w // m) * m
    return np.pad(x, ((0, 0), (0, ph - h), (0, pw - w)), mode="edge")


def infer(session: ort.InferenceSession, meta: dict, x: np.ndarray) -> np.ndarray:
    """Step 3: the network's per-tile values, (len(outputs), tiles high, tiles wide) on the padded grid."""
    feed, first, graph_inputs = {}, 0, session.get_inputs()
    for graph_input in graph_inputs:
        # one input takes every plane (its plane count may be free); several each their fixed count
        planes = len(meta["inputs"]) if len(graph_inputs) == 1 else graph_input.shape[1]
        feed[graph_input.name] = np.ascontiguousarray(x[None, first:first + planes])
        first += planes
    assert first == len(meta["inputs"]), "the graph's inputs hold a different number of planes than the metadata"
    skip = {meta.get("finite_probe"), "features"}
    name = next(o.name for o in session.get_outputs() if o.name not in skip)
    return session.run([name], feed)[0][0]


def inverse_transform(p: np.ndarray, t: dict) -> np.ndarray:
    """Transformed space back to metric units (not clamped)."""
    if t["type"] == "clamped":
        return p * (2.0 * t["mu_y"])
    if t["type"] == "logistic":
        def sigmoid(v: float) -> float:  # (as tanh: 1 / (1 + exp(-v)) overflows for a steep k, k mu_y past 709)
            return 0.5 * (1.0 + float(np.tanh(0.5 * v)))  # (the SDK's form, to the bit)

        s0, s1 = sigmoid(t["k"] * (0.0 - t["mu_y"])), sigmoid(t["k"] * (1.0 - t["mu_y"]))
        s = np.clip(p * (s1 - s0) + s0, LOGIT_EPS, 1.0 - LOGIT_EPS)
        return t["mu_y"] + np.log(s / (1.0 - s)) / t["k"]
    return (p - t["offset"]) / t["factor"]  # linear


def decode(raw: np.ndarray, meta: dict) -> np.ndarray:
    """Step 4: network values to all six rates' values in metric units, float32 (6, th, tw)."""
    t, better = meta["transform"], bool(meta.get("higher_is_better", meta["metric"] == "psnr"))
    increasing = not (t["type"] == "linear" and t["factor"] < 0)
    worse = 1.0 if increasing != better else -1.0  # the direction of a worse image in transformed space
    v = dict(zip(meta["outputs"], inverse_transform(raw.astype(np.float64) + worse * meta.get("safety", 0.0), t)))
    k = meta.get("extrapolation_k", 2.13)
    if better:  # a quality in dB: worse is lower, and k times the error's amplitude is 20 log10 k dB less
        pick, scaled = np.minimum, (lambda a: a - 20.0 * math.log10(k))
    else:
        pick, scaled = np.maximum, (lambda a: a * k)
    if tuple(meta["outputs"]) == ("2x2",):
        v["1x2"] = v["2x1"] = v["2x2"]
    v.setdefault("2x2", pick(v["1x2"], v["2x1"]))
    v.setdefault("2x4", pick(scaled(v["1x2"]), v["2x2"]))
    v.setdefault("4x2", pick(scaled(v["2x1"]), v["2x2"]))
    v.setdefault("4x4", pick(v["2x4"], v["4x2"]))
    return np.stack([v[r] for r in RATES]).astype(np.float32)


def hardware_tiles(values: np.ndarray, meta: dict, tile_size: int, frame: tuple[int, int]) -> np.ndarray:
    """Step 5: (6, th, tw) on the model's tiles to the hardware's ``tile_size``-pixel tiles."""
    own, (h, w) = meta["tile_size"], frame
    if tile_size >= own:  # coarser: the worst model tile of each hardware tile (NaN stays NaN: full rate)
        f = tile_size // own
        th, tw = values.shape[1:]
        ch, cw = -(-th // f), -(-tw // f)
        better = bool(meta.get("higher_is_better", meta["metric"] == "psnr"))
        grid = np.full((6, ch * f, cw * f), np.inf if better else -np.inf, np.float32)
        grid[:, :th, :tw] = values
        blocks = grid.reshape(6, ch, f, cw, f)
        return blocks.min(axis=(2, 4)) if better else blocks.max(axis=(2, 4))
    f = own // tile_size  # finer: each takes its model tile's values, cropped to the frame's finer grid
    return values.repeat(f, axis=1).repeat(f, axis=2)[:, :-(-h // tile_size), :-(-w // tile_size)]


def select(values: np.ndarray, meta: dict, threshold: float, allowed: tuple[str, ...] = RATES) -> np.ndarray:
    """Step 6: per tile the cheapest allowed rate whose value passes its threshold, else 1x1 (uint8 codes)."""
    better = bool(meta.get("higher_is_better", meta["metric"] == "psnr"))
    factors = meta.get("rate_factors") or {}
    codes = np.zeros(values.shape[1:], np.uint8)  # 1x1
    done = np.zeros(values.shape[1:], bool)
    # cost classes, cheapest first: 4x4; 2x4 and 4x2; 2x2; 1x2 and 2x1
    for group in (("4x4",), ("2x4", "4x2"), ("2x2",), ("1x2", "2x1")):
        best = np.full(values.shape[1:], np.inf)
        for rate in (r for r in group if r in allowed):
            f = float(factors.get(rate, 1.0))
            v = values[RATES.index(rate)].astype(np.float64)
            # as "smaller is better": the value over its threshold's factor (PSNR: minus, plus the dB)
            e = (-v - 20.0 * math.log10(f)) if better else v / f
            ok = ~done & (e < (-threshold if better else threshold)) & (e < best)  # NaN passes nothing
            codes[ok], best[ok] = CODES[rate], e[ok]
        done |= best < np.inf
    return codes


def select_for_saving(values: np.ndarray, meta: dict, saving: float, allowed: tuple[str, ...] = RATES,
                      frame: tuple[int, int] | None = None, tile_size: int | None = None,
                      threshold: float | None = None, engine: np.ndarray | None = None,
                      combiner: str = "max") -> tuple[np.ndarray, float]:
    """Step 7: the rates that save ``saving`` of the frame's work (each tile weighed by its pixels, given the
    ``frame``'s (H, W) and ``tile_size``) at the lowest threshold that does, and that threshold; with a
    ``threshold`` too, the saving is a floor under it (the higher of the two thresholds; PSNR the lower). Beside
    the ``engine``'s rates (step 8) the saving is the device's: the engine's and the image's together."""
    if engine is None:
        reached = _budget(values, meta, saving, allowed, frame, tile_size)
    else:
        reached = _budget_beside(values, meta, saving, allowed, frame, tile_size, engine, combiner)
    better = bool(meta.get("higher_is_better", meta["metric"] == "psnr"))
    if threshold is not None and (threshold <= reached if better else threshold >= reached):  # it saves enough
        reached = threshold
    if engine is None:
        return select(values, meta, reached, allowed), reached
    return select_beside(values, meta, reached, engine, combiner, allowed), reached


def _weights(th: int, tw: int, frame: tuple[int, int] | None, tile_size: int | None) -> np.ndarray:
    """Each tile's pixels (partial edge tiles count theirs), or 1 each without the frame's size."""
    if frame is None or tile_size is None:
        return np.ones((th, tw))
    (h, w), t = frame, tile_size
    return np.outer(np.minimum(t, h - t * np.arange(th)), np.minimum(t, w - t * np.arange(tw))).astype(float)


def _reaching(steps: np.ndarray, gain: np.ndarray, need: float, better: bool) -> float:
    """The lowest threshold past which the steps' gains add up to ``need`` (the most the frame can save where
    they do not: NaN tiles never pass), as "smaller passes" turned back to the metric's direction."""
    lowest = -1e6 if better else 0.0  # the lowest threshold there is (as "smaller is better"), and the highest
    at, gain = steps.ravel(), gain.ravel()
    useful = (at < 1e6) & (gain > 0)  # (NaN tiles and values past 1e6 never pass; a step that adds nothing is no step)
    at, gain = at[useful], gain[useful]
    if need <= 0 or at.size == 0:
        return -lowest if better else lowest
    order = np.argsort(at, kind="stable")
    total = np.cumsum(gain[order])
    j = min(int(np.searchsorted(total, need)), at.size - 1)
    t = float(np.clip(np.nextafter(at[order][j], np.inf), lowest, 1e6))
    return -t if better else t


def _budget(values: np.ndarray, meta: dict, saving: float, allowed: tuple[str, ...],
            frame: tuple[int, int] | None, tile_size: int | None) -> float:
    """Step 7 without a threshold: the lowest threshold that saves ``saving``."""
    better = bool(meta.get("higher_is_better", meta["metric"] == "psnr"))
    factors = meta.get("rate_factors") or {}
    th, tw = values.shape[1:]
    weights = _weights(th, tw, frame, tile_size)
    steps, shares = [], []
    # cost classes, dearest first: the best value (over its factor, "smaller is better") of each, NaN never passing
    for group, share in ((("1x2", "2x1"), 0.5), (("2x2",), 0.75), (("2x4", "4x2"), 0.875), (("4x4",), 0.9375)):
        best = np.full((th, tw), np.inf)
        for rate in (r for r in group if r in allowed):
            f = float(factors.get(rate, 1.0))
            v = values[RATES.index(rate)].astype(np.float64)
            e = (-v - 20.0 * math.log10(f)) if better else v / f
            best = np.where(np.isnan(e), best, np.minimum(best, e))
        if any(r in allowed for r in group):
            steps.append(best)
            shares.append(share)
    if not steps:
        return _reaching(np.zeros(0), np.zeros(0), 0.0, better)
    # a tile saves at least a class's share once the threshold passes the best value of that class or a cheaper one
    at = np.minimum.accumulate(np.stack(steps)[::-1], axis=0)[::-1]
    gain = np.diff(shares, prepend=0.0)[:, None, None] * weights
    return _reaching(at, gain, saving * weights.sum() * (1.0 - 1e-12), better)


def _budget_beside(values: np.ndarray, meta: dict, saving: float, allowed: tuple[str, ...],
                   frame: tuple[int, int] | None, tile_size: int | None, engine: np.ndarray, combiner: str) -> float:
    """Step 7 beside step 8: per tile, what the engine's rate saves alone is saved at any threshold, and each cost
    class adds its share past that once the threshold passes the best value of the candidates the device shades
    at that class or a cheaper one."""
    better = bool(meta.get("higher_is_better", meta["metric"] == "psnr"))
    th, tw = values.shape[1:]
    weights = _weights(th, tw, frame, tile_size)
    supported, oriented = _candidates(values, meta, allowed)
    classes = (2, 4, 8, 16)
    steps = np.full((len(classes), th, tw), np.inf)
    alone = np.ones((th, tw))  # the area of the rate the engine's gives alone (the 1x1 candidate's)
    names = {c: r for r, c in CODES.items()}
    for code in np.unique(engine):
        tiles = engine == code
        for c in supported:
            got = _shaded(names[int(code)], c, combiner, supported)
            area = SIZES[got[0]][0] * SIZES[got[0]][1]
            if c == "1x1":
                alone[tiles] = area
            if area > 1:
                value = np.maximum(oriented[got[0]], oriented[got[-1]])  # the worse of two (a NaN never passes)
                k = classes.index(area)
                steps[k] = np.where(tiles & ~np.isnan(value), np.minimum(steps[k], value), steps[k])
    steps = np.minimum.accumulate(steps[::-1], axis=0)[::-1]  # a class or a cheaper one
    forced = 1.0 - 1.0 / alone
    lifted = np.maximum(np.array([1.0 - 1.0 / a for a in classes])[:, None, None], forced)
    gain = np.diff(lifted, axis=0, prepend=forced[None]) * weights
    need = saving * weights.sum() * (1.0 - 1e-12) - float((forced * weights).sum())
    return _reaching(steps, gain, need, better)


SIZES = {"1x1": (1, 1), "1x2": (1, 2), "2x1": (2, 1), "2x2": (2, 2), "2x4": (2, 4), "4x2": (4, 2), "4x4": (4, 4)}


def device_rates(w: int, h: int, supported: tuple[str, ...]) -> tuple[str, ...]:
    """Step 8's clamp: the rates a device may shade where a combiner asks for ``w x h``, the first the one it
    reports: that rate where supported; else, of the supported rates inside it, the largest, then the squarest
    (the tall one first of a wide and a tall one); then any other a device that also tries the swapped axes
    may take (Vulkan allows it)."""
    if (w, h) in [SIZES[r] for r in supported]:
        return (next(r for r in supported if SIZES[r] == (w, h)),)

    def largest(swapped: bool) -> list[str]:
        fits = [r for r in SIZES if r in supported and ((SIZES[r][0] <= w and SIZES[r][1] <= h)
                                                       or (swapped and SIZES[r][0] <= h and SIZES[r][1] <= w))]
        top = max(SIZES[r][0] * SIZES[r][1] for r in fits)
        fits = [r for r in fits if SIZES[r][0] * SIZES[r][1] == top]
        return [r for r in fits if sum(SIZES[r]) == min(sum(SIZES[q]) for q in fits)]

    inside = largest(False)
    return tuple(inside + [r for r in largest(True) if r not in inside])


def _candidates(values: np.ndarray, meta: dict, allowed: tuple[str, ...]) -> tuple[tuple[str, ...], dict]:
    """The rates a device has (1x1 and the allowed ones) and every rate's value per tile as "smaller passes",
    against its own threshold (1x1: -inf, it always passes)."""
    better = bool(meta.get("higher_is_better", meta["metric"] == "psnr"))
    factors = meta.get("rate_factors") or {}
    oriented = {"1x1": np.full(values.shape[1:], -np.inf)}
    for r in RATES:
        f, v = float(factors.get(r, 1.0)), values[RATES.index(r)].astype(np.float64)
        oriented[r] = (-v - 20.0 * math.log10(f)) if better else v / f
    return ("1x1",) + tuple(r for r in RATES if r in allowed), oriented


def _shaded(engine: str, candidate: str, combiner: str, supported: tuple[str, ...]) -> tuple[str, ...]:
    """The rates a device may shade where ``combiner`` meets the engine's rate and a candidate of the image."""
    (ew, eh), (cw, ch) = SIZES[engine], SIZES[candidate]
    ask = {"min": (min(ew, cw), min(eh, ch)), "max": (max(ew, cw), max(eh, ch)), "sum": (ew * cw, eh * ch)}
    return device_rates(*ask[combiner], supported)


def select_beside(values: np.ndarray, meta: dict, threshold: float, engine: np.ndarray, combiner: str,
                  allowed: tuple[str, ...] = RATES) -> np.ndarray:
    """Step 8: the image's rates (uint8 codes) where the engine's own rates ``engine`` (codes, a tile each) meet it
    in the hardware's ``combiner`` ("min", "max" or "sum"): per tile the cheapest rate the device shades whose
    value passes, then the better value, then one the device shades as judged; else the engine's rate alone.
    The image holds the rate shaded where combining it with the engine's gives it back (min, max), else the
    finest rate that gives the same."""
    better = bool(meta.get("higher_is_better", meta["metric"] == "psnr"))
    supported, oriented = _candidates(values, meta, allowed)
    # the candidates: the allowed rates by cost class, cheapest first, then 1x1 (what the engine's rate gives alone)
    order = [r for r in ("4x4", "2x4", "4x2", "2x2", "1x2", "2x1") if r in supported] + ["1x1"]
    thr = -threshold if better else threshold
    names = {c: r for r, c in CODES.items()}
    out = np.zeros(values.shape[1:], np.uint8)
    for code in np.unique(engine):
        e = names[int(code)]
        tiles = engine == code
        outcome = {c: _shaded(e, c, combiner, supported) for c in order}
        best = np.full(values.shape[1:], -1)
        best_area = np.zeros(values.shape[1:])
        best_value = np.full(values.shape[1:], np.inf)
        best_exact = np.zeros(values.shape[1:], bool)
        for k, c in enumerate(order):
            got = outcome[c]
            value = np.maximum(oriented[got[0]], oriented[got[-1]])  # (np.maximum keeps a NaN: it never passes)
            area, exact = SIZES[got[0]][0] * SIZES[got[0]][1], len(got) == 1
            wins = (value < thr) & ((best < 0) | (area > best_area) | ((area == best_area) & (
                (value < best_value) | ((value == best_value) & exact & ~best_exact))))
            best = np.where(wins, k, best)
            best_area = np.where(wins, area, best_area)
            best_value = np.where(wins, value, best_value)
            best_exact = np.where(wins, exact, best_exact)
        best = np.where(best < 0, len(order) - 1, best)  # nothing passes: the engine's rate alone
        for k, c in enumerate(order):
            got = outcome[c]
            same = [q for q in order if outcome[q] == got]
            image = got[0] if got[0] in same else min(same, key=lambda q: (SIZES[q][0] * SIZES[q][1], list(SIZES).index(q)))
            out[tiles & (best == k)] = CODES[image]
    return out


def shading_rates(session: ort.InferenceSession, x: np.ndarray, threshold: float | None = None,
                  tile_size: int | None = None, allowed: tuple[str, ...] = RATES, saving: float | None = None,
                  engine: np.ndarray | None = None, combiner: str = "max") -> np.ndarray:
    """Steps 1-6 (7 with a ``saving``, 8 with the ``engine``'s rates): a frame's planes (C, H, W), float32, to its
    shading-rate image."""
    meta = read_metadata(session)
    _, h, w = x.shape
    raw = infer(session, meta, pad(x, meta, session))
    t = meta["tile_size"]
    values = decode(raw, meta)[:, :-(-h // t), :-(-w // t)]  # the tiles of the frame, not of its padding
    if tile_size is not None and tile_size != t:
        values = hardware_tiles(values, meta, tile_size, (h, w))
    if saving is not None:
        beside = None if engine is None else np.broadcast_to(engine, values.shape[1:])
        return select_for_saving(values, meta, saving, allowed, (h, w), tile_size or t, threshold, beside,
                                 combiner)[0]
    if engine is not None:
        threshold = meta["default_threshold"] if threshold is None else threshold
        return select_beside(values, meta, threshold, np.broadcast_to(engine, values.shape[1:]), combiner, allowed)
    return select(values, meta, meta["default_threshold"] if threshold is None else threshold, allowed)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model", type=Path, help="an rtp ONNX model file")
    ap.add_argument("--frame", type=Path, help="the input planes, a (C, H, W) float32 .npy (default: a random frame)")
    ap.add_argument("--size", default="1280x720", help="the random frame's WIDTHxHEIGHT (default 1280x720)")
    ap.add_argument("--threshold", type=float, help="default: the model's default_threshold")
    ap.add_argument("--saving", type=float, help="a budget instead (step 7): the share of the shading work to save; "
                    "with --threshold, a floor under the threshold's rates")
    ap.add_argument("--engine-rate", choices=tuple(CODES), help="step 8: the engine's own rate over the whole frame "
                    "(a per-draw rate), which --combiner meets with the image")
    ap.add_argument("--combiner", choices=("min", "max", "sum"), default="max", help="step 8's combiner (default max)")
    ap.add_argument("--tile-size", type=int, choices=(4, 8, 16, 32),
                    help="the hardware's shading-rate tile size (default: the model's)")
    ap.add_argument("--allowed", default=",".join(RATES), help="the reduced rates the hardware has (default: all six)")
    ap.add_argument("--check", action="store_true", help="compare with rtp.sdk's shading_rates on the same frame")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(message)s")  # (step 2's warning; --check's SDK says it too)

    if not a.model.is_file():
        ap.error(f"no model file at {str(a.model)!r}")
    try:
        session = ort.InferenceSession(str(a.model), providers=["CPUExecutionProvider"])
        meta = read_metadata(session)
    except Exception as err:  # (onnxruntime's errors are its own classes; a file that is no ONNX model, no metadata)
        ap.error(f"{a.model}: cannot be read as an rtp ONNX model ({type(err).__name__}: {err})")
    if a.frame is not None:
        try:
            x = np.load(a.frame, allow_pickle=False)
        except (OSError, ValueError) as err:  # a missing file, a folder, not a .npy (or a pickle)
            ap.error(f"--frame: cannot read {str(a.frame)!r} as a .npy array ({type(err).__name__}: {err})")
        if not isinstance(x, np.ndarray) or x.dtype != np.float32 or x.ndim != 3 or len(x) != len(meta["inputs"]) \
                or 0 in x.shape:
            ap.error(f"--frame: expected float32 planes ({len(meta['inputs'])}, H, W) for {meta['inputs']}, H and W at "
                     f"least 1, got {getattr(x, 'dtype', type(x).__name__)} {getattr(x, 'shape', '')}")
        bad = ~np.isfinite(x)
        if bad.any():  # (the SDK refuses it: NonFiniteInputError; the port alone would give those tiles 1x1)
            where = tuple(int(i) for i in np.argwhere(bad)[0])
            ap.error(f"--frame: holds {int(bad.sum())} NaN or infinite values (first at {where}, plane "
                     f"{meta['inputs'][where[0]]!r})")
    else:
        try:
            w, h = (int(v) for v in a.size.lower().split("x"))
        except ValueError:
            w = h = 0
        if min(w, h) < 1:
            ap.error(f"--size: expected WIDTHxHEIGHT such as 1280x720, got {a.size!r}")
        x = np.random.default_rng(0).random((len(meta["inputs"]), h, w), dtype=np.float32)
        if "seen" in meta["inputs"]:  # a mask: 0 or 1
            x[meta["inputs"].index("seen")] = x[meta["inputs"].index("seen")] > 0.2
    fixed = fixed_size(session)
    if fixed is not None and (x.shape[1] > fixed[0] or x.shape[2] > fixed[1]):
        ap.error(f"{'--frame' if a.frame is not None else '--size'}: the model has a fixed input of {fixed[1]}x"
                 f"{fixed[0]}, a {x.shape[2]}x{x.shape[1]} frame does not fit (smaller ones are padded up to it)")
    allowed = tuple(r.strip() for r in a.allowed.split(",") if r.strip())
    unknown = [r for r in allowed if r not in RATES]
    if unknown:
        ap.error(f"--allowed: {', '.join(unknown)} is no reduced rate; the rates are {', '.join(RATES)}")
    twice = [r for r in dict.fromkeys(allowed) if allowed.count(r) > 1]
    if twice:
        ap.error(f"--allowed: each rate once, got {', '.join(twice)} more than once in {a.allowed!r}")
    better = bool(meta.get("higher_is_better", meta["metric"] == "psnr"))
    low = -MAX_THRESHOLD if better else 0.0  # (an error below 0 or past 1e6 is refused by the SDK: ParameterError)
    if a.threshold is not None and not low <= a.threshold <= MAX_THRESHOLD:
        ap.error(f"--threshold: expected a finite number in [{low:g}, {MAX_THRESHOLD:g}] "
                 f"{'dB (higher is better)' if better else 'for an error metric (lower is better)'}, got {a.threshold:g}")
    top = max((1.0 - 1.0 / (SIZES[r][0] * SIZES[r][1]) for r in allowed), default=0.0)  # the coarsest allowed rate's
    if a.saving is not None and not 0.0 <= a.saving <= top:
        ap.error(f"--saving: expected a share of the shading work in [0, {top:g}] (what the coarsest allowed rate "
                 f"saves), got {a.saving:g}")
    if a.engine_rate is not None and a.engine_rate not in ("1x1", *allowed):
        ap.error(f"--engine-rate: {a.engine_rate} is not among the rates allowed ({', '.join(('1x1', *allowed))}): a device "
                 "shades a rate of its own choice for it")
    engine = None if a.engine_rate is None else np.uint8(CODES[a.engine_rate])
    rates = shading_rates(session, x, a.threshold, a.tile_size, allowed, a.saving, engine, a.combiner)
    names = {c: r for r, c in CODES.items()}
    counts = {names[c]: int(n) for c, n in zip(*np.unique(rates, return_counts=True))}
    print(f"{a.model.name}: {rates.shape[0]}x{rates.shape[1]} tiles; " + ", ".join(f"{r} {n}" for r, n in counts.items()))
    if a.check:
        from rtp import sdk

        predictor = sdk.load(a.model, tile_size=a.tile_size)
        theirs = predictor.shading_rates(x, a.threshold, allowed=allowed, saving=a.saving, engine_rates=engine,
                                         combiner=a.combiner)
        same = float(np.mean(theirs == rates))
        print(f"rtp.sdk gives the same rate on {100 * same:.2f}% of the tiles")
        return 0 if same == 1.0 else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
