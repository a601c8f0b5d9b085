"""The classic content-adaptive shading methods as rate selectors, for comparison with a model.

Each selector has the predictor's interface (``predict`` -> per-tile values ``(6, th, tw)`` in
:data:`rtp.sdk.PREDICTED_RATES` order, ``shading_rates`` -> uint8 D3D12/Vulkan codes
``(th, tw)``) but reads a frame instead of a model input tensor: a :class:`~rtp.capture.Sample`, a
:class:`Frame`, a mapping of buffers (``reprojected``, ``motion``, ``seen``) or a bare reprojected
``(H, W, 3)`` image.

* :class:`Yang2019`: NVIDIA Adaptive Shading (Yang et al., I3D 2019; docs/evaluation.md).
* :class:`FidelityFX`: AMD FidelityFX Variable Shading (FidelityFX-VariableShading, docs/evaluation.md).
* :class:`ModelSelector` and :class:`Oracle`: the model (through ``rtp.sdk``) and the true targets
  behind the same interface, so one loop compares all of them.

Everything is vectorised numpy over tiles; see docs/evaluation.md for the parameters and what each
method cannot do.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, Protocol

import numpy as np

from rtp.metrics import DEFAULT_WEBER_L
from rtp.sdk import (
    DEFAULT_EXTRAPOLATION_K,
    DEFAULT_TILE_SIZE,
    EXIT_USAGE,
    LUMA_WEIGHTS,
    MAX_THRESHOLD,
    METRICS,
    PREDICTED_RATES,
    RATE_CODES,
    InputDtypeError,
    InputError,
    InputShapeError,
    NonFiniteInputError,
    ParameterError,
    RateLike,
    RtpError,
    check_threshold,
    rate_size,
    resolve_allowed,
    select_rates,
    tile_grid,
)

if TYPE_CHECKING:
    from rtp.capture import TargetStore
    from rtp.sdk import ShadingRatePredictor

__all__ = [
    "FFX_LUMA",
    "BaselineError",
    "FidelityFX",
    "Frame",
    "ModelSelector",
    "Oracle",
    "RateSelector",
    "Yang2019",
    "as_frame",
    "motion_factor_half",
    "motion_factor_quarter",
    "restrict_rates",
]

#: The baselines' default parameters, one home for the library, rtp evaluate and rtp play: Yang 2019's
#: sensitivity (JNYang units, RT-Percept's 0.25: JNYang's default threshold, ``sdk.METRICS["jnyang"]``), FidelityFX's
#: cutoff (luma) and its motion factor (per pixel of motion per frame). Yang's environment luminance is the Weber
#: ``l`` of the JN metrics, ``rtp.metrics.DEFAULT_WEBER_L``.
YANG_THRESHOLD = METRICS["jnyang"].default_threshold
FFX_CUTOFF = 0.05
FFX_MOTION_FACTOR = 0.05

log = logging.getLogger("rtp.evaluate")

#: FidelityFX VRS's own luma weights (Yang 2019 uses Rec.601, :data:`rtp.sdk.LUMA_WEIGHTS`).
FFX_LUMA = (0.30, 0.59, 0.11)


class BaselineError(RtpError, ValueError):
    """A baseline got a frame it cannot use (missing buffer, bad shape) or a bad parameter."""

    exit_code = EXIT_USAGE


# -- frames -------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Frame:
    """What the classic methods read.

    ``reprojected``: the previous final frame fetched at each pixel's previous position, float32
    ``(H, W, 3)`` display-encoded in [0, 1], 0 where unseen. ``motion``: screen motion in pixels
    ``(H, W, 2)`` (x right, y down) or None. ``seen``: ``(H, W)`` in [0, 1] or None.
    """

    reprojected: np.ndarray
    motion: np.ndarray | None = None
    seen: np.ndarray | None = None
    #: Terms computed from ``motion`` and ``seen`` alone (per-tile speeds, unseen shares), keyed by the
    #: method's parameters: frames given the same dict share them. For callers that run many methods on
    #: one camera frame with different reprojected images (``rtp play``'s closed loop: each method's
    #: own history); a dict must not outlive the ``motion`` and ``seen`` arrays it was filled from.
    terms: dict[Any, np.ndarray] | None = field(default=None, compare=False, repr=False)

    @property
    def size(self) -> tuple[int, int]:
        """``(H, W)``."""
        return int(self.reprojected.shape[0]), int(self.reprojected.shape[1])

    def term(self, key: Any, compute: Any) -> np.ndarray:
        """``compute()``, or the value frames sharing :attr:`terms` already computed for ``key``."""
        if self.terms is None:
            return compute()
        got = self.terms.get(key)
        if got is None:
            got = np.asarray(compute())
            got.flags.writeable = False  # shared: a method that changed it would change the others' input
            self.terms[key] = got
        return got


def as_real(value: Any, what: str, dtype: Any = None) -> np.ndarray:
    """``value`` as an array of real numbers (of ``dtype`` when given), or an ``InputDtypeError`` naming
    ``what``: a ragged list, strings or objects were numpy's ValueError or TypeError."""
    try:
        a = np.asarray(value, dtype=dtype)
    except (TypeError, ValueError, OverflowError) as err:
        raise InputDtypeError(f"{what}: expected numbers, got {type(value).__name__} ({err})") from err
    if a.dtype.kind not in "biuf":
        raise InputDtypeError(f"{what}: expected real numbers, got dtype {a.dtype}")
    return a


def as_frame(source: Any) -> Frame:
    """A :class:`Frame` from a Sample, a Frame, a mapping of buffers or a reprojected image."""
    if isinstance(source, Frame):
        frame = source
    elif isinstance(source, np.ndarray):
        frame = Frame(source)
    elif isinstance(source, Mapping):
        if "reprojected" not in source:
            raise BaselineError("a frame mapping needs a 'reprojected' (H, W, 3) image")
        frame = Frame(source["reprojected"], source.get("motion"), source.get("seen"))
    elif hasattr(source, "buffer"):  # an rtp.capture.Sample (or anything with its buffer())
        motion = seen = None
        try:
            motion = source.buffer("motion")
        except RtpError:
            log.debug("sample %s has no motion buffer; the baselines assume a static camera", getattr(source, "id", "?"))
        try:
            seen = source.buffer("seen")
        except RtpError:
            pass
        frame = Frame(source.buffer("reprojected"), motion, seen)
    else:
        raise BaselineError(
            f"expected a Sample, a Frame, a mapping of buffers or an (H, W, 3) array, got {type(source).__name__}"
        )
    raw = as_real(frame.reprojected, "reprojected", None) if not isinstance(frame.reprojected, np.ndarray) \
        else frame.reprojected
    if not (isinstance(source, Frame) and source.__dict__.get("_checked")):  # (one checked here before: passed on)
        if raw.dtype.kind != "f":  # uint8 0-255 read as colours in [0, 1]: FidelityFX chose 1x1 everywhere
            raise InputDtypeError(f"reprojected: expected float colours in [0, 1], got dtype {raw.dtype} "
                                  "(an 8-bit image: image / 255)")
        if raw.size:  # (two reductions: NaN makes both NaN; NaN made Yang 2019 choose 4x4 everywhere)
            lo, hi = float(raw.min()), float(raw.max())
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise NonFiniteInputError("reprojected: holds NaN or infinite values; expected colours in [0, 1]")
            if lo < -1e-3 or hi > 1 + 1e-3:  # (HDR values were read as colours: 4x4 everywhere)
                raise InputError(f"reprojected: values in [{lo:.4g}, {hi:.4g}], expected display-encoded colours "
                                      "in [0, 1] (tone-mapped, sRGB-encoded: the frame as shown)")
    rep = as_real(raw, "reprojected", np.float32)
    if rep.ndim != 3 or rep.shape[2] < 3 or rep.shape[0] == 0 or rep.shape[1] == 0:
        raise InputShapeError(f"reprojected: expected (H, W, 3), got {rep.shape}", tuple(rep.shape), "(H, W, 3)")
    h, w = rep.shape[:2]
    motion = None if frame.motion is None else as_real(frame.motion, "motion", np.float32)
    if motion is not None and motion.shape != (h, w, 2):
        raise InputShapeError(f"motion: expected {(h, w, 2)}, got {motion.shape}", tuple(motion.shape), f"({h}, {w}, 2)")
    seen = None if frame.seen is None else as_real(frame.seen, "seen", np.float32)
    if seen is not None and seen.shape != (h, w):
        raise InputShapeError(f"seen: expected {(h, w)}, got {seen.shape}", tuple(seen.shape), f"({h}, {w})")
    if not (isinstance(source, Frame) and source.__dict__.get("_checked")):
        # (an infinite speed made Yang 2019's tile 4x4 and FidelityFX's 1x1, NaN both 1x1; a 0/255 seen mask read
        # every tile as seen, so Yang2019(unseen="full") shaded none at full rate: all silently)
        if motion is not None and motion.size and not np.isfinite(motion).all():
            raise NonFiniteInputError("motion: holds NaN or infinite values; expected finite screen motion in pixels "
                                      "(0 where there is none)")
        if seen is not None and seen.size:
            lo, hi = float(seen.min()), float(seen.max())
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise NonFiniteInputError("seen: holds NaN or infinite values; expected a mask in [0, 1]")
            if lo < -1e-3 or hi > 1 + 1e-3:
                raise InputError(f"seen: values in [{lo:.4g}, {hi:.4g}], expected a mask in [0, 1] (1 seen, 0 unseen; "
                                 "an 8-bit mask: mask / 255)")
    return _checked(Frame(rep[..., :3], motion, seen, terms=frame.terms))


def _checked(frame: Frame) -> Frame:
    """``frame``, marked as one whose reprojected image holds display colours and whose motion and seen mask are
    finite (the mask in [0, 1]): :func:`as_frame` checked them, or the caller made them so (``rtp play``'s closed
    loop, from each method's own displayed frame and the renderer's buffers)."""
    object.__setattr__(frame, "_checked", True)
    return frame


# -- tile helpers -------------------------------------------------------------------------------


def _pad_to_tiles(a: np.ndarray, t: int, mode: str = "edge") -> np.ndarray:
    """``a`` (``(H, W[, C])``) padded up to whole tiles (edge copies, or zeros); ``a`` itself when the
    frame is whole tiles already (no copy: the closed loop calls this for every method and frame)."""
    h, w = a.shape[:2]
    th, tw = tile_grid(h, w, t)
    if (th * t, tw * t) == (h, w):
        return a
    pad = ((0, th * t - h), (0, tw * t - w)) + ((0, 0),) * (a.ndim - 2)
    return np.pad(a, pad, mode=mode)  # type: ignore[call-overload]


def _frame_tile(t: int, size: tuple[int, int]) -> int:
    """The tile side to pool a frame of ``size`` with: ``t``, or the frame's longer side when ``t`` is
    larger (the same one tile per axis, without padding up to ``t x t`` pixels)."""
    return min(t, max(size))


def _blocks(a: np.ndarray, t: int, mode: str = "edge") -> np.ndarray:
    """``(H, W)`` -> ``(th, t, tw, t)``, padded up to whole tiles (edge copies, or zeros)."""
    p = _pad_to_tiles(a, t, mode)
    return p.reshape(p.shape[0] // t, t, p.shape[1] // t, t)


def _tile_mean(a: np.ndarray, t: int) -> np.ndarray:
    """Per-tile mean over the pixels the frame holds (partial edge tiles included)."""
    sums = _blocks(a.astype(np.float64, copy=False), t, mode="constant").sum(axis=(1, 3))
    h, w = a.shape
    if h % t == 0 and w % t == 0:
        return sums / float(t * t)
    return sums / _blocks(np.ones(a.shape, np.float64), t, mode="constant").sum(axis=(1, 3))


def _cell_reduce(a: np.ndarray, ch: int, cw: int, fn: Any = np.maximum) -> np.ndarray:
    """``fn`` (``np.maximum`` or ``np.minimum``) over each ``ch x cw`` cell of a 2D array whose sides are
    multiples of them: ``(H / ch, W / cw)``. Elementwise extremes of strided views, which give exactly
    what ``.max(axis=(1, 3))`` of the ``(H/ch, ch, W/cw, cw)`` reshape gives in about a third to a tenth of
    its time (a reduction over two short axes is slow in numpy); the closed loop runs these for every
    method and frame."""
    cols = fn(a[:, 0::cw], a[:, 1::cw]) if cw > 1 else a.copy()
    for i in range(2, cw):
        fn(cols, a[:, i::cw], out=cols)
    if ch == 1:
        return cols
    rows = fn(cols[0::ch], cols[1::ch])
    for i in range(2, ch):
        fn(rows, cols[i::ch], out=rows)
    return rows


def _max_abs_step(p: np.ndarray, t: int, axis: int) -> np.ndarray:
    """The largest absolute difference of neighbours along ``axis`` (0: rows, 1: columns) inside each
    ``t x t`` tile of ``p`` (sides multiples of ``t``): ``(H / t, W / t)``. Pairs that straddle two tiles
    count as 0, which leaves every tile's maximum as it is (the differences are >= 0)."""
    d = np.empty(p.shape, p.dtype)
    if axis == 0:
        np.subtract(p[1:], p[:-1], out=d[:-1])
        d[t - 1::t] = 0.0
    else:
        np.subtract(p[:, 1:], p[:, :-1], out=d[:, :-1])
        d[:, t - 1::t] = 0.0
    np.abs(d, out=d)
    return _cell_reduce(d, t, t)


def _luma(rgb: np.ndarray, weights: tuple[float, float, float]) -> np.ndarray:
    r, g, b = weights
    return (r * rgb[..., 0] + g * rgb[..., 1] + b * rgb[..., 2]).astype(np.float64)


def _check_tile(tile: int, allowed: Iterable[int] | None = None) -> int:
    if isinstance(tile, bool) or not isinstance(tile, (int, np.integer)) or tile < 2:
        raise BaselineError(f"tile_size must be an integer >= 2, got {tile!r}")
    if allowed is not None and int(tile) not in tuple(allowed):
        raise BaselineError(f"tile_size must be one of {tuple(allowed)}, got {tile}")
    return int(tile)


def _flag(owner: str, name: str, value: Any) -> bool:
    """A baseline's on/off parameter as a bool, or a BaselineError: any other value was read by its truth, so
    ``motion="false"`` (a text from a settings file) switched the motion terms on."""
    if not isinstance(value, (bool, np.bool_)):
        raise BaselineError(f"{owner} {name}: expected True or False, got {value!r}")
    return bool(value)


def _real_param(owner: str, name: str, value: Any) -> float:
    """A baseline's parameter as a float, or a BaselineError (a string or None was compared, an int past
    float's range converted)."""
    try:
        if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise TypeError
        return float(value)
    except (TypeError, OverflowError):
        raise BaselineError(f"{owner} {name}: expected a number, got {value!r}") from None


def restrict_rates(codes: np.ndarray, allowed: Iterable[RateLike] | None, estimates: np.ndarray | None = None) -> np.ndarray:
    """Demote rates that ``allowed`` excludes to the coarsest allowed rate that is not coarser on
    either axis (1x1 at worst). Between equally cheap candidates (2x4 and 4x2 for a forbidden 4x4)
    the one with the smaller ``estimates`` value wins when estimates ``(6, th, tw)`` are given, else
    the first in channel order."""
    ok = set(resolve_allowed(allowed))
    if ok == set(PREDICTED_RATES):
        return codes
    codes = as_real(codes, "codes")
    if codes.dtype != np.uint8 or codes.ndim < 1 or int(codes.max(initial=0)) > max(RATE_CODES.values()):
        raise ParameterError(f"codes: expected uint8 rate codes ({', '.join(f'{r} {c}' for r, c in RATE_CODES.items())}), "
                             f"got {codes.dtype} {codes.shape}", "codes")
    if estimates is not None:
        estimates = as_real(estimates, "estimates", np.float64)
        if estimates.shape != (len(PREDICTED_RATES), *codes.shape):
            raise InputShapeError(f"estimates: expected {(len(PREDICTED_RATES), *codes.shape)}, got {estimates.shape}",
                                  tuple(estimates.shape), f"(6, {', '.join(map(str, codes.shape))})")
    out = codes.copy()
    for rate in PREDICTED_RATES:
        if rate in ok:
            continue
        mask = codes == RATE_CODES[rate]
        if not mask.any():
            continue
        w, h = rate_size(rate)
        cands = [r for r in ok if rate_size(r)[0] <= w and rate_size(r)[1] <= h]
        if not cands:
            out[mask] = 0
            continue
        best_area = max(rate_size(r)[0] * rate_size(r)[1] for r in cands)
        ties = [r for r in PREDICTED_RATES if r in cands and rate_size(r)[0] * rate_size(r)[1] == best_area]
        if len(ties) == 1 or estimates is None:
            out[mask] = RATE_CODES[ties[0]]
        else:
            e = np.stack([estimates[PREDICTED_RATES.index(r)] for r in ties])
            pick = np.asarray([RATE_CODES[r] for r in ties], np.uint8)[np.argmin(e, axis=0)]
            out[mask] = pick[mask]
    return out


# -- the common interface -------------------------------------------------------------------------


class RateSelector(Protocol):
    """What the evaluation needs of a method: a name, a tile size, per-tile values and rates."""

    name: str
    tile_size: int

    def predict(self, source: Any) -> np.ndarray:  # (6, th, tw)
        ...

    def shading_rates(self, source: Any, threshold: float | None = None, allowed: Iterable[RateLike] | None = None) -> np.ndarray:
        ...


# -- Yang et al. 2019 ---------------------------------------------------------------------------


def motion_factor_half(v: np.ndarray | float) -> np.ndarray:
    """Yang 2019 Eq. 20: ``b_H(v) = (1 + (1.05 v)^3.10)^-0.35`` for a speed ``v`` in pixels/frame
    (1 at rest, about 0.047 at 16 px)."""
    v = np.abs(np.asarray(v, dtype=np.float64))
    return np.power(1.0 + np.power(1.05 * v, 3.10), -0.35)


def motion_factor_quarter(v: np.ndarray | float, k: float = DEFAULT_EXTRAPOLATION_K) -> np.ndarray:
    """Yang 2019 Eq. 21: ``b_Q(v) = k (1 + (0.55 v)^2.41)^-0.49`` with ``k = 2.13`` (the
    quarter-rate error ratio at rest; about 0.163 at 16 px)."""
    v = np.abs(np.asarray(v, dtype=np.float64))
    return k * np.power(1.0 + np.power(0.55 * v, 2.41), -0.49)


Norm = Literal["max", "rms"]


class Yang2019:
    """NVIDIA Adaptive Shading (Yang et al. 2019) on the reprojected previous frame.

    Per tile and axis a half-rate error ``E_H`` of the Rec.601 luma of the reprojected frame:

    * ``norm="max"`` (default): the largest absolute difference of neighbouring pixels inside the
      tile, as NVIDIA's shipping NAS shader and RT-Percept's YangVRS compute it. With
      point-sampled coarse shading (which the dataset renders) a half-rate tile's per-pixel error
      is exactly such a difference, so this is on the scale of the max-pooled JNYang target.
    * ``norm="rms"``: the paper's Eq. 2, the RMS over the tile of half the neighbour differences
      (needs a lower ``threshold``).

    Estimates are Weber-normalised, ``E / (mean tile luma + env_luminance)``, i.e. in JNYang-like
    units, and multiplied by the motion factors ``b_H(v)`` (half rates) and ``b_Q(v)`` (quarter
    rates, ``k = 2.13`` at rest; never below ``b_H``) of the per-tile speed along the same axis.
    Channel ``WxH`` is the larger of its two per-axis estimates, so ``shading_rates`` (the cheapest rate whose estimate is
    below ``threshold``) equals the paper's per-axis decision OR-combined, with 4x1/1x4 demoted to
    2x1/1x2 (they are no D3D12 rates) and, with ``allow_4x4=False`` (NAS), 4x4 replaced by 2x4 or
    4x2 keeping the axis with the larger error finer.

    Unseen tiles: the reprojection is black there (0), so ``E = 0`` and the estimate is 0: the
    coarsest rate, exactly what RT-Percept's YangVRS does (``unseen="as_is"``, the default). With
    ``unseen="full"`` tiles whose unseen share exceeds ``unseen_fraction`` get ``+inf`` estimates,
    so 1x1 (the behaviour the paper's Section 5.2 ascribes to the method); that needs the seen mask.
    """

    name = "yang2019"
    #: The metric whose units the estimates approximate.
    metric = "jnyang"

    def __init__(
        self,
        tile_size: int = DEFAULT_TILE_SIZE,
        *,
        threshold: float = YANG_THRESHOLD,
        env_luminance: float = DEFAULT_WEBER_L,
        norm: Norm = "max",
        k: float = DEFAULT_EXTRAPOLATION_K,
        motion: bool = True,
        motion_scale: float = 1.0,
        motion_reduce: Literal["min", "mean", "max"] = "min",
        allow_4x4: bool = True,
        unseen: Literal["as_is", "full"] = "as_is",
        unseen_fraction: float = 0.5,
    ) -> None:
        self.tile_size = _check_tile(tile_size)
        if norm not in ("max", "rms"):
            raise BaselineError(f"norm must be 'max' or 'rms', got {norm!r}")
        if motion_reduce not in ("min", "mean", "max"):
            raise BaselineError(f"motion_reduce must be min, mean or max, got {motion_reduce!r}")
        if unseen not in ("as_is", "full"):
            raise BaselineError(f"unseen must be 'as_is' or 'full', got {unseen!r}")
        threshold, env_luminance, k, motion_scale, unseen_fraction = (
            _real_param("Yang 2019's", name, value) for name, value in (
                ("threshold", threshold), ("env_luminance", env_luminance), ("k", k), ("motion_scale", motion_scale),
                ("unseen_fraction", unseen_fraction)))
        for name, value, ok, expected in (
                # (0 as the models take it, and as its shading_rates(threshold=0) did: nothing is below it, all 1x1)
                ("threshold", threshold, 0 <= threshold <= MAX_THRESHOLD,
                 f"in [0, {MAX_THRESHOLD:g}] (its JNYang threshold)"),
                ("env_luminance", env_luminance, env_luminance >= 0, ">= 0"), ("k", k, k >= 1, ">= 1"),
                ("motion_scale", motion_scale, motion_scale >= 0, ">= 0"),
                ("unseen_fraction", unseen_fraction, 0 <= unseen_fraction < 1, "in [0, 1)")):
            if not ok:  # (NaN fails every comparison)
                raise BaselineError(f"Yang 2019's {name}: expected a number {expected}, got {value!r}")
        motion, allow_4x4 = _flag("Yang 2019's", "motion", motion), _flag("Yang 2019's", "allow_4x4", allow_4x4)
        self.threshold, self.env_luminance, self.norm, self.k = float(threshold), float(env_luminance), norm, float(k)
        self.motion, self.motion_scale, self.motion_reduce = motion, float(motion_scale), motion_reduce
        self.allow_4x4, self.unseen, self.unseen_fraction = allow_4x4, unseen, float(unseen_fraction)
        if unseen == "full":
            self.name = "yang2019-unseen-1x1"

    def params(self) -> dict[str, Any]:
        """The parameters, for reports."""
        return {
            "tile_size": self.tile_size, "threshold": self.threshold, "env_luminance": self.env_luminance,
            "norm": self.norm, "k": self.k, "motion": self.motion, "motion_scale": self.motion_scale,
            "motion_reduce": self.motion_reduce, "allow_4x4": self.allow_4x4, "unseen": self.unseen,
            "unseen_fraction": self.unseen_fraction, "luma": "rec601",
        }

    def __repr__(self) -> str:
        return f"<Yang2019 tile={self.tile_size} t={self.threshold:g} l={self.env_luminance:g} norm={self.norm}>"

    def half_rate_error(self, source: Any) -> tuple[np.ndarray, np.ndarray]:
        """Per-tile half-rate errors ``(2, th, tw)`` in luma units, ``[E_y (1x2), E_x (2x1)]``,
        and the per-tile mean luma ``(th, tw)``. Only neighbour pairs inside a tile count."""
        frame = as_frame(source)
        t = _frame_tile(self.tile_size, frame.size)
        lum = _luma(frame.reprojected, LUMA_WEIGHTS)
        # vertical neighbours -> error of halving vertically (1x2); horizontal -> 2x1
        if self.norm == "max":
            p = _pad_to_tiles(lum, t)  # edge-padded: padded pairs differ by 0
            e_y, e_x = _max_abs_step(p, t, 0), _max_abs_step(p, t, 1)
        else:
            b = _blocks(lum, t)  # (th, t, tw, t), edge-padded: padded pairs differ by 0
            dy, dx = np.abs(np.diff(b, axis=1)), np.abs(np.diff(b, axis=3))
            m = _blocks(np.ones(lum.shape), t, mode="constant")
            my, mx = m[:, 1:] * m[:, :-1], m[..., 1:] * m[..., :-1]
            e_y = np.sqrt(((0.5 * dy) ** 2 * my).sum(axis=(1, 3)) / np.maximum(my.sum(axis=(1, 3)), 1.0))
            e_x = np.sqrt(((0.5 * dx) ** 2 * mx).sum(axis=(1, 3)) / np.maximum(mx.sum(axis=(1, 3)), 1.0))
        return np.stack([e_y, e_x]), _tile_mean(lum, t)

    def tile_motion(self, source: Any) -> np.ndarray:
        """Per-tile speed per axis ``(2, th, tw)`` in pixels/frame, ``[|v_y|, |v_x|]`` (zeros
        without motion or with ``motion=False``), reduced over the tile by ``motion_reduce``."""
        frame = as_frame(source)
        th, tw = tile_grid(*frame.size, self.tile_size)
        if not self.motion or frame.motion is None:
            return np.zeros((2, th, tw))
        return frame.term(("yang2019.tile_motion", self.tile_size, self.motion_scale, self.motion_reduce),
                          lambda: self._tile_motion(frame))

    def _tile_motion(self, frame: Frame) -> np.ndarray:
        assert frame.motion is not None
        t = _frame_tile(self.tile_size, frame.size)
        if self.motion_reduce == "mean":
            return np.stack([_tile_mean(np.abs(frame.motion[..., axis].astype(np.float64)) * self.motion_scale,
                                        t) for axis in (1, 0)])  # y then x: the 1x2, 2x1 order
        # min / max: the extreme of |v| per tile in the motion's own precision, then scaled (scaling
        # is monotone, so these are the extremes of the scaled speeds: the same values, 3x faster)
        fn = np.minimum if self.motion_reduce == "min" else np.maximum
        out = [_cell_reduce(_pad_to_tiles(np.abs(frame.motion[..., axis]), t), t, t, fn) for axis in (1, 0)]
        return np.stack(out).astype(np.float64) * self.motion_scale

    def predict(self, source: Any) -> np.ndarray:
        """Estimated error of each reduced rate, float32 ``(6, th, tw)``, JNYang-like units
        (``E / (L + l)`` with motion factors). See the class docstring."""
        frame = as_frame(source)
        (e_y, e_x), mean = self.half_rate_error(frame)
        v_y, v_x = self.tile_motion(frame)
        denom = mean + self.env_luminance
        with np.errstate(divide="ignore", invalid="ignore"):
            n_y = np.where(denom > 0, e_y / np.where(denom > 0, denom, 1.0), np.where(e_y > 0, np.inf, 0.0))
            n_x = np.where(denom > 0, e_x / np.where(denom > 0, denom, 1.0), np.where(e_x > 0, np.inf, 0.0))
        b_hy, b_hx = motion_factor_half(v_y), motion_factor_half(v_x)
        hy, hx = b_hy * n_y, b_hx * n_x
        # Eq. 16 shades an axis at quarter rate only where its half rate passes too: b_Q below b_H (speeds of
        # thousands of pixels a frame, sooner with k near 1) made 4x4 pass where 2x2 failed
        qy = np.maximum(motion_factor_quarter(v_y, self.k), b_hy) * n_y
        qx = np.maximum(motion_factor_quarter(v_x, self.k), b_hx) * n_x
        est = np.stack([hy, hx, np.maximum(hy, hx), np.maximum(hx, qy), np.maximum(qx, hy), np.maximum(qx, qy)])
        if self.unseen == "full":
            if frame.seen is None:
                raise BaselineError("Yang2019(unseen='full') needs the seen mask of the frame")
            seen = frame.seen
            t = _frame_tile(self.tile_size, frame.size)
            unseen = frame.term(("yang2019.unseen", self.tile_size), lambda: 1.0 - _tile_mean(seen, t))
            est[:, unseen > self.unseen_fraction] = np.inf
        return est.astype(np.float32)

    def shading_rates(self, source: Any, threshold: float | None = None, allowed: Iterable[RateLike] | None = None) -> np.ndarray:
        """Per tile the cheapest rate whose estimate is below ``threshold`` (default: the
        sensitivity ``t`` given at construction), else 1x1: uint8 codes ``(th, tw)``."""
        thr = self.threshold if threshold is None else check_threshold(threshold, False)
        rates = resolve_allowed(allowed)
        if not self.allow_4x4:
            rates = tuple(r for r in rates if r != "4x4")
        return select_rates(self.predict(source), thr, allowed=rates)


# -- AMD FidelityFX VRS -------------------------------------------------------------------------

FFX_TILE_SIZES = (8, 16, 32)


def _neighbour_reduce(a: np.ndarray, fn: Any) -> np.ndarray:
    """``fn`` over the 4-neighbourhood (up, down, left, right; edges clamped) of a 2D grid."""
    p = np.pad(a, 1, mode="edge")
    return fn(fn(p[:-2, 1:-1], p[2:, 1:-1]), fn(p[1:-1, :-2], p[1:-1, 2:]))


class FidelityFX:
    """AMD FidelityFX Variable Shading on the reprojected previous frame (docs/evaluation.md).

    Luma ``0.30 R + 0.59 G + 0.11 B``. The dataset's reprojected frame stands in for FFX's fetch of
    the previous frame at ``pos - round(mv)``; like FFX it does not know what is unseen (black there,
    so coarse).

    Base path (``additional_rates=False``, rates 1x1, 1x2, 2x1, 2x2): per 2x2 coarse pixel
    ``a b / c d``: ``dx = max(|a-b|, |c-d|)``, ``dy = max(|a-c|, |b-d|)``, ``dz = max - min``; all
    three and the coarse pixel's max lose ``|mv| * motion_factor`` (``|mv|`` the mean motion length
    of the 2x2 in pixels); anti-burn-in: ``d += max(0, min - min of the 4 neighbours' minima) +
    max(0, max of the neighbours' maxima - max)``, clamped at 0; per-tile max; then ``dz < c`` ->
    2x2, else ``dx > dy`` -> 1x2 if ``dy <= c`` else 1x1, else 2x1 if ``dx <= c`` else 1x1.

    Additional-rates path (``additional_rates=True``): per 4x4 block the luma ranges of its aligned
    sub-blocks of each rate (the largest range over the sub-blocks, i.e. the error of shading each
    sub-block once), minus ``|mv| * motion_factor``, tested against ``c`` in the order 4x4, 4x2,
    2x4, 2x2, 2x1, 1x2; then each block takes, per axis, the finest rate of itself and its 4
    neighbours, and each tile the finest of its blocks. (FFX's code takes the minimum of the rate codes
    instead of the finest rate per axis, and the FidelityFX SDK's copy of it computes "dy" like "dx" in
    this path, where FidelityFX-VariableShading 1.0 reads vertical pairs as rtp does; FFX starts
    the quarter-rate sub-blocks' min/max at ``(cutoff, 0)``; none of this is reproduced, nor its
    tile bookkeeping or its motion read at one pixel: docs/evaluation.md "Where it departs from FFX's
    shader".)

    ``predict`` returns the per-tile luma deltas in channel order (``[dy, dx, dz, inf, inf, inf]``
    on the base path; the six sub-block ranges on the other), absolute display-luma units: they are
    decision variables, not estimates of a perceptual metric.
    """

    name = "fidelityfx"
    metric = None

    def __init__(
        self,
        tile_size: int = DEFAULT_TILE_SIZE,
        *,
        cutoff: float = FFX_CUTOFF,
        motion_factor: float = FFX_MOTION_FACTOR,
        additional_rates: bool = False,
    ) -> None:
        self.tile_size = _check_tile(tile_size, FFX_TILE_SIZES)
        cutoff, motion_factor = (_real_param("FidelityFX's", n, v) for n, v in (("cutoff", cutoff),
                                                                                 ("motion_factor", motion_factor)))
        if not (cutoff >= 0 and motion_factor >= 0):
            raise BaselineError(f"cutoff and motion_factor must be >= 0, got {cutoff}, {motion_factor}")
        additional_rates = _flag("FidelityFX's", "additional_rates", additional_rates)
        self.cutoff, self.motion_factor, self.additional_rates = float(cutoff), float(motion_factor), additional_rates
        if additional_rates:
            self.name = "fidelityfx-additional"

    def params(self) -> dict[str, Any]:
        return {"tile_size": self.tile_size, "cutoff": self.cutoff, "motion_factor": self.motion_factor,
                "additional_rates": self.additional_rates, "luma": "0.30/0.59/0.11"}

    def __repr__(self) -> str:
        return (f"<FidelityFX tile={self.tile_size} cutoff={self.cutoff:g} motion_factor={self.motion_factor:g} "
                f"additional={self.additional_rates}>")

    def _padded(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """Luma and motion length, padded (edge) up to whole tiles: ``(Hp, Wp)`` each."""
        t = self.tile_size
        lum = _pad_to_tiles(_luma(frame.reprojected, FFX_LUMA), t)
        if frame.motion is None:
            speed = np.zeros_like(lum)
        else:
            motion = frame.motion
            speed = frame.term(("fidelityfx.speed", t), lambda: _pad_to_tiles(
                np.hypot(motion[..., 0], motion[..., 1]).astype(np.float64), t))
        return lum, speed

    def _per_tile(self, a: np.ndarray, cells: int, fn: str = "max") -> np.ndarray:
        """Reduce a grid with ``cells`` cells per tile side to ``(th, tw)``."""
        return _cell_reduce(a, cells, cells, np.maximum if fn == "max" else np.minimum)

    def _base(self, frame: Frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        lum, speed = self._padded(frame)
        a, b, c, d = lum[0::2, 0::2], lum[0::2, 1::2], lum[1::2, 0::2], lum[1::2, 1::2]
        sub = self.motion_factor * 0.25 * (speed[0::2, 0::2] + speed[0::2, 1::2] + speed[1::2, 0::2] + speed[1::2, 1::2])
        dx = np.maximum(np.abs(a - b), np.abs(c - d)) - sub
        dy = np.maximum(np.abs(a - c), np.abs(b - d)) - sub
        lo = np.minimum(np.minimum(a, b), np.minimum(c, d))
        hi = np.maximum(np.maximum(a, b), np.maximum(c, d))
        dz = hi - lo - sub
        hi = hi - sub
        pad = np.maximum(0.0, lo - _neighbour_reduce(lo, np.minimum)) + np.maximum(0.0, _neighbour_reduce(hi, np.maximum) - hi)
        cells = self.tile_size // 2
        return tuple(self._per_tile(np.maximum(0.0, v + pad), cells) for v in (dx, dy, dz))  # type: ignore[return-value]

    def _additional(self, frame: Frame) -> np.ndarray:
        """Per 4x4 block the sub-block ranges ``(6, Hp/4, Wp/4)`` in channel order, motion subtracted."""
        lum, speed = self._padded(frame)
        hp, wp = lum.shape
        # The max and min of every aligned w-wide, h-tall sub-block, each rate's from a smaller one's
        # (halving the columns or the rows): a few passes over the frame instead of a reduction per rate.
        hi: dict[tuple[int, int], np.ndarray] = {(1, 1): lum}
        lo: dict[tuple[int, int], np.ndarray] = {(1, 1): lum}
        for w, h in ((2, 1), (1, 2), (2, 2), (4, 2), (2, 4), (4, 4)):
            if (w // 2, h) in hi:  # pairs of columns
                src = (w // 2, h)
                hi[w, h] = np.maximum(hi[src][:, 0::2], hi[src][:, 1::2])
                lo[w, h] = np.minimum(lo[src][:, 0::2], lo[src][:, 1::2])
            else:  # pairs of rows
                src = (w, h // 2)
                hi[w, h] = np.maximum(hi[src][0::2], hi[src][1::2])
                lo[w, h] = np.minimum(lo[src][0::2], lo[src][1::2])

        def rng(w: int, h: int) -> np.ndarray:  # largest range over the aligned w-wide, h-tall sub-blocks
            return _cell_reduce(hi[w, h] - lo[w, h], 4 // h, 4 // w)

        sub = self.motion_factor * speed.reshape(hp // 4, 4, wp // 4, 4).mean(axis=(1, 3))
        ranges = np.stack([rng(*rate_size(r)) for r in PREDICTED_RATES]) - sub
        return np.maximum(ranges, 0.0)

    def predict(self, source: Any) -> np.ndarray:
        """Per-tile luma deltas ``(6, th, tw)`` float32 in channel order (see the class docstring)."""
        frame = as_frame(source)
        if not self.additional_rates:
            dx, dy, dz = self._base(frame)
            inf = np.full(dx.shape, np.inf)
            return np.stack([dy, dx, dz, inf, inf, inf]).astype(np.float32)
        ranges = self._additional(frame)
        cells = self.tile_size // 4
        return np.stack([self._per_tile(r, cells) for r in ranges]).astype(np.float32)

    def shading_rates(self, source: Any, threshold: float | None = None, allowed: Iterable[RateLike] | None = None) -> np.ndarray:
        """FFX's rate decision with cutoff ``threshold`` (default ``cutoff``): uint8 codes ``(th, tw)``.
        Rates outside ``allowed`` are demoted (:func:`restrict_rates`)."""
        # (nan chose 1x1 everywhere and -1 refused every reduced rate, both silently)
        c = self.cutoff if threshold is None else check_threshold(threshold, False)
        frame = as_frame(source)
        if not self.additional_rates:
            dx, dy, dz = self._base(frame)
            out = np.where(
                dz < c, RATE_CODES["2x2"],
                np.where(dx > dy, np.where(dy <= c, RATE_CODES["1x2"], 0), np.where(dx <= c, RATE_CODES["2x1"], 0)),
            ).astype(np.uint8)
            est = np.stack([dy, dx, dz, *(np.full(dx.shape, np.inf),) * 3])
            return restrict_rates(out, allowed, est)
        ranges = self._additional(frame)
        order = ("4x4", "4x2", "2x4", "2x2", "2x1", "1x2")
        block = np.zeros(ranges.shape[1:], np.uint8)
        decided = np.zeros(block.shape, bool)
        for r in order:
            take = ~decided & (ranges[PREDICTED_RATES.index(r)] < c)
            block[take] = RATE_CODES[r]
            decided |= take
        # Per axis the finest of the block and its 4 neighbours, then of the tile's blocks.
        ax_x, ax_y = block >> 2, block & 3
        ax_x = np.minimum(ax_x, _neighbour_reduce(ax_x, np.minimum))
        ax_y = np.minimum(ax_y, _neighbour_reduce(ax_y, np.minimum))
        cells = self.tile_size // 4
        tx, ty = self._per_tile(ax_x, cells, "min"), self._per_tile(ax_y, cells, "min")
        h, w = frame.size
        th, tw = tile_grid(h, w, self.tile_size)
        out = ((tx << 2) | ty).astype(np.uint8)[:th, :tw]
        est = np.stack([self._per_tile(r, cells) for r in ranges])
        return restrict_rates(out, allowed, est)


# -- the model and the truth behind the same interface ------------------------------------------


class ModelSelector:
    """A loaded :class:`~rtp.sdk.ShadingRatePredictor` that reads a Sample the way an engine feeds
    it: ``predictor.predict(sample.inputs(metadata.inputs))``."""

    def __init__(self, predictor: ShadingRatePredictor, name: str = "model") -> None:
        self.predictor, self.name = predictor, name
        self.tile_size = predictor.tile_size

    def _x(self, source: Any) -> np.ndarray:
        if isinstance(source, np.ndarray):
            return source
        return source.inputs(self.predictor.metadata.inputs)

    def predict(self, source: Any) -> np.ndarray:
        return self.predictor.predict(self._x(source))

    def shading_rates(self, source: Any, threshold: float | None = None, allowed: Iterable[RateLike] | None = None) -> np.ndarray:
        return self.predictor.shading_rates(self._x(source), threshold, allowed)


class Oracle:
    """The true per-tile targets of a dataset as a selector: the best any predictor can do."""

    name = "oracle"

    def __init__(
        self, store: TargetStore, metric: str, tile_size: int, *, threshold: float, higher_is_better: bool = False
    ) -> None:
        self.store, self.metric, self.tile_size = store, metric, _check_tile(tile_size)
        # (checked here, as the other selectors' are: "x" was a bare ValueError, -1 refused only at the first frame)
        self.threshold = check_threshold(threshold, higher_is_better)
        self.higher_is_better = bool(higher_is_better)

    def predict(self, source: Any) -> np.ndarray:
        return self.store.load(source.id, self.metric, self.tile_size)

    def shading_rates(self, source: Any, threshold: float | None = None, allowed: Iterable[RateLike] | None = None) -> np.ndarray:
        thr = self.threshold if threshold is None else check_threshold(threshold, self.higher_is_better)
        return select_rates(self.predict(source), thr, higher_is_better=self.higher_is_better, allowed=allowed)
