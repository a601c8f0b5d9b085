"""The runtime's per-tile decision as a GLSL compute shader (``shaders/select_rates_cs.glsl``).

``ShadingRatePredictor.shading_rates`` decodes the network's output and picks the rates on the CPU
(numpy). An engine that runs the network on the GPU wants the decision there too, so the prediction
never travels back: :class:`RateSelector` runs the same rules (``ModelMetadata.decode``, then
``select_rates``) in one compute dispatch, from the network's raw output in a GPU buffer to the
shading-rate image, an ``r8ui`` texture of D3D12 / Vulkan rate codes. It is also the reference to port:
the shader is 100 lines of GLSL 4.30 and its results are tested against the SDK's. A budget
(``saving=``, ``sdk.select_rates_for_saving``) adds a dispatch between the decode and the selection
(``shaders/select_budget_cs.glsl``) that finds the threshold on the GPU.
"""

from __future__ import annotations

import logging
import math
import threading
import warnings
from collections.abc import Iterable
from typing import Any

import numpy as np

from rtp import sdk
from rtp.sdk.adapters import AdapterFrameError

from ._glio import CurrentCheck, is_released, max_texture_side, warn_not_freed
from ._renderer import RendererError, create_context
from ._shaders import load_source

__all__ = ["RateSelector"]


def _tile_pair(value: object, name: str) -> tuple[int, int]:
    """``value`` as (rows, columns) of at least one tile each, or a ParameterError naming ``name``."""
    pair: list[int] = []
    try:
        pair = [int(v) for v in value if isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))]  # type: ignore[attr-defined]
        n = len(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        n = 0
    if n != 2 or len(pair) != 2 or min(pair) < 1:
        raise sdk.ParameterError(f"{name}: expected (rows, columns) of at least one tile, got {value!r}", name)
    return pair[0], pair[1]  # Python ints: numpy's int64 rows of 2**62 wrapped the byte count below 0

def _frame_with_budget(saving: object, frame_size: object) -> None:
    """A ``frame_size`` weighs a budget's tiles: given without a ``saving``, it would weigh nothing."""
    if saving is None and frame_size is not None:
        raise sdk.ParameterError("frame_size: it weighs a budget's tiles by their pixels; give it with saving=",
                                 "frame_size")


_TRANSFORMS = {"clamped": 0, "logistic": 1, "linear": 2}
#: The combiners through which the image's rate reaches the frame, at the enum values of D3D12 and Vulkan (the SDK
#: checks a name or value before it is looked up here).
_COMBINER_VALUES: dict[str | int, int] = {"min": 2, "max": 3, "sum": 4, "mul": 4, 2: 2, 3: 3, 4: 4}
_GROUP = 8  # the shader's local size, both axes
#: The most thresholds a selector logs its once-each threshold warnings of, as the SDK's predictor (its MAX_WARNED): a
#: controller that moves the threshold every frame is not warned every frame.
_MAX_WARNED = 16
log = logging.getLogger("rtp.plugins.moderngl")


def _split_float32(value: float) -> tuple[float, float]:
    """``value`` as float32 high and low parts whose sum is ``value`` to float64's precision: a shader adds
    them in turn where one float32 would lose what a cancellation leaves."""
    high = float(np.float32(value))
    return high, float(np.float32(value - high))


class RateSelector:
    """The decision of ``ShadingRatePredictor.shading_rates`` on the GPU, for one model's metadata.

    ``model`` is an ``sdk.ShadingRatePredictor`` (its metadata and hardware tile size are taken) or an
    ``sdk.ModelMetadata``; ``ctx`` a moderngl context of OpenGL 4.3 or later (compute shaders; default: a
    new headless one through EGL). ``tile_size`` is the hardware's shading-rate tile when it differs
    from the model's (``sdk.load(..., tile_size=)``): coarser, each hardware tile takes the worst of the
    model tiles it covers (``sdk.pool_tiles``); finer (AMD's and Intel's 8-pixel tiles under a 16-pixel
    model), each takes its model tile's values (``sdk.split_tiles``), on the frame's grid of hardware
    tiles given as ``grid``. Default: the predictor's, or the model's own tiles::

        selector = RateSelector(predictor, ctx)
        rates = selector.select(predictor.predict_raw(x))          # (th, tw) uint8, as shading_rates(x)
        texture = selector.select_buffer(raw_buffer, (th, tw))     # stays on the GPU: an r8ui texture
        rates = selector.select(raw, grid=predictor.tiles(h, w))   # finer hardware tiles: the frame's grid

    The shader computes in float32 where the SDK decodes in float64, so a tile whose value lies within
    float32 rounding of the threshold (or of the other rate of its cost class) can decide the other
    way; everywhere else the codes are the SDK's.

    Close it (or use it in a ``with`` block): :meth:`close` frees its GL objects, and the context when it made
    its own. A selector dropped unclosed says so with a ``ResourceWarning``; a context it made is then released
    with it, while in a borrowed one its objects stay until that context goes.
    """

    def __init__(self, model: sdk.ShadingRatePredictor | sdk.ModelMetadata, ctx: Any | None = None,
                 tile_size: int | None = None) -> None:
        meta = model.metadata if isinstance(model, sdk.ShadingRatePredictor) else model
        if not isinstance(meta, sdk.ModelMetadata):
            raise sdk.ParameterError(f"RateSelector: expected an sdk.ShadingRatePredictor or sdk.ModelMetadata, got "
                                     f"{type(model).__name__}", "model")
        if tile_size is None:
            tile_size = model.tile_size if isinstance(model, sdk.ShadingRatePredictor) else meta.tile_size
        allowed_tiles = sdk.hardware_tiles(meta.tile_size)
        if isinstance(tile_size, (bool, np.bool_)) or not isinstance(tile_size, (int, np.integer)) \
                or int(tile_size) not in allowed_tiles:
            raise sdk.ParameterError(f"tile_size: expected one of {list(allowed_tiles)} (the hardware's shading-rate "
                                     f"tile for the model's {meta.tile_size}-pixel tiles), got {tile_size!r}",
                                     "tile_size")
        tile_size = int(tile_size)  # (numpy's integers, as a grid computation hands them, are tile sizes too)
        self._meta = meta
        # what the threshold warnings name the model by (the predictor's file, as its own warnings do), the thresholds
        # warned of and the last (threshold, budget) judged
        path = model.path if isinstance(model, sdk.ShadingRatePredictor) else None
        self._name = path.name if path is not None else "model"
        self._warned: set[float] = set()
        self._judged: tuple[float, bool] | None = None
        #: model tiles per hardware tile side (coarser hardware tiles; else 1)
        self.pool = max(1, tile_size // meta.tile_size)
        #: hardware tiles per model tile side (finer hardware tiles; else 1)
        self.split = max(1, meta.tile_size // tile_size)
        if ctx is not None and is_released(ctx):
            raise AdapterFrameError("ctx: this moderngl context has been released; pass a live one (or none: the "
                                    "selector then makes its own)")
        if ctx is not None and not callable(getattr(ctx, "compute_shader", None)):
            raise AdapterFrameError(f"ctx must be a moderngl.Context, got {type(ctx).__name__}")
        # Every GL object's slot before any is made: close() frees what a constructor that failed part-way made.
        self._program: Any = None
        self._tiles: tuple[int, int] | None = None
        self._texture: Any = None
        self._decoded: Any = None
        self._raw: Any = None
        self._engine: Any = None
        self._budget_program: Any = None  # (compiled on the first budget)
        self._budget: Any = None
        self._budget_work: float | None = None  # the frame's work, in pixels (tiles), of the last budget
        # Whether its context is the one current in the calling thread, read back where a call comes from another
        # thread than the last (_glio.CurrentCheck: moderngl's ctx.__enter__() does not say when the driver refused it)
        self._current: CurrentCheck | None = None
        self._own_ctx = False
        self.ctx = create_context(430) if ctx is None else ctx
        self._own_ctx = ctx is None
        try:
            self._build(meta)
        except BaseException:  # (the context it made and the objects so far: the caller never gets the selector)
            self.close()
            raise

    def _build(self, meta: sdk.ModelMetadata) -> None:
        """The constructor's GL part: the decision's program and its uniforms, in the selector's context."""
        self.ctx.__enter__()  # (a borrowed context may not be the current one: the programs are made in it)
        self._current = CurrentCheck(
            self.ctx, "RateSelector", "could not be made current",
            "Call the selector from the thread where the context is current, or release it there first "
            "(ctx.__exit__(None, None, None)); or give each thread a selector of its own context")
        if self.ctx.version_code < 430:
            raise RendererError(f"RateSelector needs compute shaders (OpenGL 4.3), got a context of version "
                                f"{self.ctx.version_code // 100}.{self.ctx.version_code % 100 // 10}")
        self._program = self.ctx.compute_shader(load_source("select_rates_cs.glsl"))
        t = meta.transform
        outputs = [sdk.PREDICTED_RATES.index(r) for r in meta.outputs]
        uniforms: dict[str, Any] = {
            "u_outputs": tuple(outputs + [-1] * (6 - len(outputs))),
            "u_shift": meta.worse_direction * meta.safety,
            "u_transform": _TRANSFORMS[t.type],
            "u_k": meta.extrapolation_k,
            "u_higher_is_better": meta.higher_is_better,
            "u_pool": self.pool,
            "u_split": self.split,
            "u_rate_factors": tuple(float(f) for f in meta.rate_factors),
        }
        if t.type in ("clamped", "logistic"):
            uniforms["u_mu_y"] = float(t.mu_y)  # type: ignore[arg-type]
        if t.type == "logistic":
            k, mu = float(t.k), float(t.mu_y)  # type: ignore[arg-type]
            uniforms["u_logistic_k"] = k
            shift = meta.worse_direction * meta.safety
            s0, s1 = 1.0 / (1.0 + math.exp(k * mu)), 1.0 / (1.0 + math.exp(-k * (1.0 - mu)))
            span = s1 - s0
            s1c = 1.0 / (1.0 + math.exp(k * (1.0 - mu)))  # 1 - S(1), not 1 - s1: that cancels where S(1) is near 1
            uniforms["u_logistic_span"] = span
            uniforms["u_logistic_a"] = _split_float32(shift + s0 / span)  # S = span (x + a)
            uniforms["u_logistic_b"] = _split_float32(s1c / span - shift)  # 1 - S = span ((1 - x) + b)
        if t.type == "linear":
            uniforms.update(u_factor=float(t.factor), u_offset=float(t.offset))  # type: ignore[arg-type]
        for name, value in uniforms.items():
            if name in self._program:
                self._program[name].value = value
        self._budget = self.ctx.buffer(reserve=8)  # the budget's threshold and the work it saves

    @property
    def metadata(self) -> sdk.ModelMetadata:
        return self._meta

    @property
    def tile_size(self) -> int:
        """The hardware tile the rates are for (pixels per side)."""
        return self._meta.tile_size * self.pool // self.split

    def _targets(self, tiles: tuple[int, int]) -> None:
        """The rate texture and the decoded buffer for a grid of hardware ``tiles`` (rows, columns)."""
        if self._tiles == tiles:
            return
        for obj in (self._texture, self._decoded):
            if obj is not None:
                obj.release()
        # (forgotten before the new ones are made: a failed allocation left them released but held, and the next
        # call of the same grid used them, of another grid released them again: an AttributeError either way)
        self._texture = self._decoded = self._tiles = None
        th, tw = tiles
        self._texture = self.ctx.texture((tw, th), 1, dtype="u1")
        self._decoded = self.ctx.buffer(reserve=6 * th * tw * 4)
        self._tiles = tiles

    def select_buffer(self, raw: Any, tiles: tuple[int, int], threshold: float | None = None,
                      allowed: Iterable[sdk.RateLike] | None = None, grid: tuple[int, int] | None = None, *,
                      engine_rates: Any = None, combiner: str | int = "max", saving: float | None = None,
                      frame_size: tuple[int, int] | None = None) -> Any:
        """Rates from the network's output already on the GPU: ``raw`` a moderngl buffer holding the
        output planes of one frame, float32 ``(len(metadata.outputs), th, tw)`` row-major, ``tiles``
        ``(th, tw)`` on the model's tiles. Returns the ``r8ui`` texture of rate codes, one texel a hardware
        tile (texel row 0 the top tile row); it is reused by the next call of the same grid. On coarser
        hardware tiles the grid is ``ceil(th / pool) x ceil(tw / pool)``; on finer ones it is the frame's,
        ``grid`` = ``(rows, columns)`` (``predictor.tiles(h, w)``: a partial last model tile may hold one
        hardware row or column fewer than ``split``), by default ``split`` times the model's tiles.

        ``engine_rates`` (one code, a ``(rows, columns)`` array of codes on the hardware tiles, or an ``r8ui``
        moderngl texture of them already on the GPU, which is read as it is) and ``combiner`` (``min``,
        ``max``, ``sum`` or its enum value): the engine's own rates, which the hardware's combiner meets with
        this image; the shader then judges the rate the device will shade, as ``sdk.select_rates(engine_rates=,
        combiner=)`` does (docs/runtime.md "The engine's own rates: the hardware's combiners"). Under a budget it
        may not be the selector's own rate texture (the one this returns), which the first dispatch overwrites.

        ``saving``: a budget instead of a threshold, as ``sdk.select_rates_for_saving`` and ``shading_rates(x,
        saving=)``: the rates of the lowest threshold that saves at least that share of the shading work, found on
        the GPU (a second dispatch, one workgroup, no read-back; :meth:`budget` reads the threshold and the saving
        back where wanted). ``frame_size = (H, W)`` weighs partial edge tiles by their pixels (without it every
        hardware tile counts alike); a ``threshold`` with it is a floor under the budget, as in the SDK. Beside
        ``engine_rates`` the saving is the device's, the engine's and the image's together, as the SDK counts it."""
        self._check_open()
        th, tw = _tile_pair(tiles, "tiles")
        grid = self._grid((th, tw), grid)
        limit = max_texture_side(self.ctx)
        if max(grid) > limit:
            raise sdk.ParameterError(f"tiles: this OpenGL context's rate texture holds at most {limit} hardware tiles "
                                     f"a side (GL_MAX_TEXTURE_SIZE), got {grid[0]}x{grid[1]} for {tiles!r}", "tiles")
        if not callable(getattr(raw, "bind_to_storage_buffer", None)) and not is_released(raw):
            raise sdk.InputDtypeError(f"raw: expected a moderngl.Buffer of the network's output, got "
                                      f"{type(raw).__name__} (select() takes an array)")
        self._check_gl_object(raw, "raw", "buffer")
        need = len(self._meta.outputs) * th * tw * 4
        if raw.size < need:
            raise sdk.InputShapeError(
                f"raw buffer holds {raw.size} bytes, expected at least {need} for {len(self._meta.outputs)} float32 "
                f"planes of {th}x{tw} tiles", (raw.size,), f"({len(self._meta.outputs)}, {th}, {tw}) float32")
        _frame_with_budget(saving, frame_size)
        thr = self._check_decision(None if saving is not None else threshold, allowed)
        budget = None if saving is None else self._check_budget(saving, threshold, allowed, grid, frame_size)
        engine = self._engine_rates(engine_rates, combiner, allowed, grid, thr, budget=saving is not None)
        mask = sum(1 << sdk.PREDICTED_RATES.index(r) for r in sdk.resolve_allowed(allowed))
        self._targets(grid)
        self._program["u_combiner"].value = 0 if engine is None else _COMBINER_VALUES[
            combiner.strip().lower() if isinstance(combiner, str) else int(combiner)]
        if engine is not None:
            if isinstance(engine, np.ndarray):  # (checked by the SDK: codes of the allowed rates, the grid's shape)
                if self._engine is None or self._engine.size != (grid[1], grid[0]):
                    if self._engine is not None:
                        self._engine.release()
                        self._engine = None  # (not held released where the new one cannot be made)
                    self._engine = self.ctx.texture((grid[1], grid[0]), 1, dtype="u1")
                self._engine.write(np.ascontiguousarray(engine, np.uint8).tobytes())
                engine = self._engine
            engine.bind_to_image(1, read=True, write=False)
        self._program["u_tiles"].value = (tw, th)
        self._program["u_grid"].value = (grid[1], grid[0])
        self._program["u_threshold"].value = float(thr)
        self._program["u_allowed"].value = mask
        self._program["u_budget"].value = False
        raw.bind_to_storage_buffer(0)
        self._decoded.bind_to_storage_buffer(1)
        self._budget.bind_to_storage_buffer(2)
        self._texture.bind_to_image(0, read=False, write=True)
        gh, gw = self._tiles  # type: ignore[misc]
        self._program.run(-(-gw // _GROUP), -(-gh // _GROUP))
        if budget is not None:  # the decoded values -> the budget's threshold -> the rates again at it
            self.ctx.memory_barrier()
            self._run_budget(budget[0], mask, threshold, grid, frame_size, self._program["u_combiner"].value)
            # (set with the dispatch, not by the checks: a call refused after them, an engine_rates of the wrong
            # grid, left budget() dividing the last budget's saving by the refused frame's work)
            self._budget_work = budget[1]
            self.ctx.memory_barrier()
            self._program["u_budget"].value = True
            self._program.run(-(-gw // _GROUP), -(-gh // _GROUP))
        # The dispatch wrote the rate image and the decoded values through image stores and storage-buffer writes,
        # which GL makes visible to nothing after them without a barrier (OpenGL 4.6 section 7.13.2): select()'s
        # glGetTexImage, decoded()'s and budget()'s buffer reads and the engine's own fetch of the image as a texture
        # or a shading-rate image could read the last frame's on a GPU (llvmpipe runs a dispatch to the end at once).
        self.ctx.memory_barrier()
        if saving is None:
            self._warn_threshold(thr, budget=False)
        elif threshold is not None:  # (a floor under the budget)
            self._warn_threshold(float(threshold), budget=True)
        return self._texture

    def _warn_threshold(self, threshold: float, *, budget: bool) -> None:
        """Log once per threshold, for the first :data:`_MAX_WARNED` thresholds, what
        ``ModelMetadata.threshold_warning`` says of it, as ``ShadingRatePredictor.shading_rates`` logs it (the same
        words, after the model's name): a threshold past the worst value the model can express (every tile at the
        coarsest rate), or past the best one (no tile passes: every tile 1x1, VRS off). Judged again only when the
        threshold or the path changes: a frame at the threshold of the frame before costs one comparison."""
        key = (threshold, budget)
        if key == self._judged:
            return
        self._judged = key
        message = self._meta.threshold_warning(threshold, budget=budget)
        if message is None or threshold in self._warned or len(self._warned) >= _MAX_WARNED:
            return
        self._warned.add(threshold)
        last = len(self._warned) >= _MAX_WARNED
        log.warning("%s: %s%s", self._name, message,
                    f" (the {_MAX_WARNED}th threshold warned of: further thresholds are not logged)" if last else "")

    def _check_budget(self, saving: float, threshold: float | None, allowed: Iterable[sdk.RateLike] | None,
                      grid: tuple[int, int], frame_size: tuple[int, int] | None) -> tuple[int, float]:
        """The work a budget must save, in sixteenths of a pixel's shading (a tile's without ``frame_size``), and the
        frame's work, in pixels (tiles), after the SDK's own checks and messages for the saving, the floor, the allowed
        rates and the frame's size."""
        sdk.select_rates_for_saving(np.zeros((6, *grid), np.float32), saving,
                                    higher_is_better=self._meta.higher_is_better, allowed=allowed,
                                    frame_size=frame_size, tile_size=None if frame_size is None else self.tile_size,
                                    threshold=threshold)
        work = float(grid[0] * grid[1]) if frame_size is None else float(frame_size[0]) * float(frame_size[1])
        # the SDK's need (a rounding's worth short counts as reached), in the shader's integers: the steps' gains
        # are sixteenths, so a sum of them reaches the need exactly where it reaches its ceiling in sixteenths
        need = math.ceil(float(saving) * work * (1.0 - 1e-12) * 16.0)
        if need > 0xFFFFFFFE:
            raise sdk.ParameterError(f"frame_size: a budget on the GPU counts up to 268 million pixels, got {work:.0f}",
                                     "frame_size")
        return need, work

    def _run_budget(self, need: int, mask: int, threshold: float | None, grid: tuple[int, int],
                    frame_size: tuple[int, int] | None, combiner: int) -> None:
        if self._budget_program is None:
            self._budget_program = self.ctx.compute_shader(load_source("select_budget_cs.glsl"))
        program = self._budget_program
        hib = self._meta.higher_is_better
        values: dict[str, Any] = {
            "u_grid": (grid[1], grid[0]),
            "u_frame": (0, 0) if frame_size is None else (int(frame_size[1]), int(frame_size[0])),
            "u_tile": self.tile_size,
            "u_higher_is_better": hib,
            "u_rate_factors": tuple(float(f) for f in self._meta.rate_factors),
            "u_allowed": mask,
            "u_need": need,
            "u_lo": -sdk.MAX_THRESHOLD if hib else 0.0,
            "u_hi": sdk.MAX_THRESHOLD,
            "u_has_floor": threshold is not None,
            "u_floor": 0.0 if threshold is None else float(threshold),
            "u_combiner": combiner,  # (the engine's texture stays bound to image unit 1 from the decode)
        }
        for name, value in values.items():
            if name in program:
                program[name].value = value
        self._decoded.bind_to_storage_buffer(1)
        self._budget.bind_to_storage_buffer(2)
        program.run(1)

    def budget(self) -> tuple[float, float]:
        """The last budget's threshold (metric units; dB for PSNR) and the share of the shading work its rates save:
        ``sdk.SavingSelection``'s ``threshold`` and ``saved``, read back from the GPU (8 bytes)."""
        self._check_open()
        if self._budget_work is None:
            raise RendererError("RateSelector.budget: no budget selected yet (select(..., saving=))")
        data = self._budget.read()
        threshold, saved = np.frombuffer(data, np.float32, 1)[0], np.frombuffer(data, np.uint32, 1, 4)[0]
        return float(threshold), float(saved) / (16.0 * self._budget_work)

    def select(self, raw: np.ndarray, threshold: float | None = None,
               allowed: Iterable[sdk.RateLike] | None = None, grid: tuple[int, int] | None = None, *,
               engine_rates: Any = None, combiner: str | int = "max", saving: float | None = None,
               frame_size: tuple[int, int] | None = None) -> np.ndarray:
        """Rates from the network's output in host memory (``ShadingRatePredictor.predict_raw``: float
        ``(C, th, tw)`` or ``(1, C, th, tw)``), computed on the GPU: uint8 codes, one per hardware tile,
        as ``shading_rates`` returns them (on finer hardware tiles than the model's, for the frame's
        ``grid``, as :meth:`select_buffer` says; ``engine_rates`` and ``combiner``, ``saving`` and ``frame_size``
        too)."""
        try:
            a = np.asarray(raw)
        except (TypeError, ValueError, OverflowError) as exc:
            raise sdk.InputShapeError(f"raw: expected the network's float output array, got {type(raw).__name__}",
                                      (), "(C, th, tw)") from exc
        if a.ndim == 4 and a.shape[0] == 1:
            a = a[0]
        n = len(self._meta.outputs)
        # Every check before the GPU is touched: moderngl refuses an empty buffer, and a failed upload left
        # the selector holding a released buffer that broke every later call.
        self._check_open()
        _frame_with_budget(saving, frame_size)
        thr = self._check_decision(None if saving is not None else threshold, allowed)
        if a.ndim == 3 and a.shape[0] == n and 0 not in a.shape:
            g = self._grid((int(a.shape[1]), int(a.shape[2])), grid)
            if saving is not None:
                self._check_budget(saving, threshold, allowed, g, frame_size)
            self._engine_rates(engine_rates, combiner, allowed, g, thr, budget=saving is not None)
        if a.ndim != 3 or a.shape[0] != n or a.dtype.kind != "f" or 0 in a.shape:
            raise sdk.InputShapeError(
                f"raw: expected the network's float output ({n}, th, tw) for outputs {list(self._meta.outputs)}, got "
                f"{a.dtype} {a.shape}", tuple(a.shape), f"({n}, th, tw)")
        with np.errstate(over="ignore"):
            data = np.ascontiguousarray(a, dtype=np.float32).tobytes()
        if self._raw is None or self._raw.size != len(data):
            if self._raw is not None:
                self._raw.release()
                self._raw = None  # (not held released where the new one cannot be made)
            self._raw = self.ctx.buffer(data)
        else:
            self._raw.write(data)
        texture = self.select_buffer(self._raw, (int(a.shape[1]), int(a.shape[2])), threshold, allowed, grid,
                                     engine_rates=engine_rates, combiner=combiner, saving=saving,
                                     frame_size=frame_size)
        gh, gw = self._tiles  # type: ignore[misc]
        return np.frombuffer(texture.read(alignment=1), np.uint8).reshape(gh, gw).copy()

    def _grid(self, tiles: tuple[int, int], grid: object) -> tuple[int, int]:
        """The hardware tiles' grid for the model's ``tiles``: ``grid`` checked, or the default."""
        th, tw = tiles
        if grid is None:
            if self.split > 1:
                return th * self.split, tw * self.split
            return -(-th // self.pool), -(-tw // self.pool)
        gh, gw = _tile_pair(grid, "grid")
        if self.split > 1:
            fits = -(-gh // self.split) == th and -(-gw // self.split) == tw
            expected = (f"{(th - 1) * self.split + 1}-{th * self.split} rows and "
                        f"{(tw - 1) * self.split + 1}-{tw * self.split} columns (the frame's {self.tile_size}-pixel "
                        f"tiles, predictor.tiles(h, w), for {th}x{tw} model tiles)")
        else:
            fits = (gh, gw) == (-(-th // self.pool), -(-tw // self.pool))
            expected = f"{-(-th // self.pool)}x{-(-tw // self.pool)} (or None) for {th}x{tw} model tiles"
        if not fits:
            raise sdk.ParameterError(f"grid: expected {expected}, got {grid!r}", "grid")
        return gh, gw

    def _check_open(self) -> None:
        """Raise when closed; else make the selector's context the current one and leave it current. moderngl never
        switches contexts by itself: a selector that ran while another context was current (a second selector's
        own, a renderer's) ran that context's objects of the same names, wrong codes or a GL error."""
        if self._program is None:
            raise RendererError("RateSelector: closed")
        if is_released(self.ctx):  # (an AttributeError from the released context, before)
            raise AdapterFrameError("ctx: the moderngl context was released under this RateSelector; build a new "
                                    "selector in a live context")
        self.ctx.__enter__()  # (moderngl's only call for it; cheap when it is current already)
        current = self._current
        if current is not None and threading.get_ident() != current.thread:
            # moderngl's ctx.__enter__() does not say when the driver refused it (the context current in another
            # thread): the calls then ran in no context and returned uninitialised memory as rate codes, in silence
            current()

    def _check_gl_object(self, obj: Any, name: str, what: str) -> None:
        """``obj`` (an engine's buffer or texture) is live and of the selector's context, else a
        :class:`rtp.sdk.ParameterError` naming ``name``: a released one failed as an ``AttributeError``, and one of
        another context was bound by its name in this one (another object's data, or none), wrong codes in silence."""
        if is_released(obj):
            raise sdk.ParameterError(f"{name}: this moderngl {what} has been released; pass a live one", name)
        if getattr(obj, "ctx", self.ctx) is not self.ctx:
            raise sdk.ParameterError(f"{name}: expected a moderngl {what} of the selector's context, got one of another "
                                     "moderngl.Context (a compute shader reads only its own context's objects)", name)

    def _check_decision(self, threshold: float | None, allowed: Iterable[sdk.RateLike] | None) -> float:
        """The threshold to use, after the SDK's own checks and messages for it and for the allowed rates
        (``select_rates`` on one tile of zeros)."""
        thr = self._meta.default_threshold if threshold is None else threshold
        sdk.select_rates(np.zeros((6, 1, 1), np.float32), thr, higher_is_better=self._meta.higher_is_better,
                         allowed=allowed)
        return float(thr)

    def _engine_rates(self, engine_rates: Any, combiner: str | int, allowed: Iterable[sdk.RateLike] | None,
                      grid: tuple[int, int], thr: float, *, budget: bool = False) -> Any:
        """None, an engine's texture as it is, or its rates as a ``grid`` array after the SDK's own checks and messages
        for them and the combiner (``select_rates`` beside them on a grid of zeros). With a ``budget``, the selector's
        own rate texture is refused: the first dispatch writes it before the budget's dispatch and the selection at
        the budget's threshold read it as the engine's rates (they read the first dispatch's rates instead)."""
        if engine_rates is None:
            return None
        if callable(getattr(engine_rates, "bind_to_image", None)) or is_released(engine_rates):
            if budget and engine_rates is self._texture:
                raise sdk.ParameterError(
                    "engine_rates: this is the selector's own rate texture, which a budget's first dispatch "
                    "overwrites before the budget and the selection read it as the engine's rates: pass the "
                    "engine's own rates (or a copy of the last frame's: select() returns one as an array)",
                    "engine_rates")
            self._check_gl_object(engine_rates, "engine_rates", "texture")
            if tuple(engine_rates.size) != (grid[1], grid[0]) or engine_rates.dtype != "u1" or engine_rates.components != 1:
                raise sdk.InputShapeError(f"engine_rates: expected an r8ui texture of {grid[1]}x{grid[0]} (one texel a "
                                          f"hardware tile), got {engine_rates.size} {engine_rates.dtype} x "
                                          f"{engine_rates.components}", tuple(engine_rates.size), f"({grid[1]}, {grid[0]})")
            sdk.select_rates(np.zeros((6, 1, 1), np.float32), thr, higher_is_better=self._meta.higher_is_better,
                             allowed=allowed, engine_rates=0, combiner=combiner)  # (the combiner's checks)
            return engine_rates
        sdk.select_rates(np.zeros((6, *grid), np.float32), thr, higher_is_better=self._meta.higher_is_better,
                         allowed=allowed, engine_rates=engine_rates, combiner=combiner)
        if isinstance(engine_rates, str):  # a rate's name, one code over the frame (checked by the SDK just above)
            engine_rates = sdk.RATE_CODES[engine_rates]
        return np.broadcast_to(np.asarray(engine_rates), grid)

    def decoded(self) -> np.ndarray:
        """The six rates' decoded values of the last call, float32 ``(6, rows, columns)`` on the hardware
        tiles (``predict``'s)."""
        self._check_open()
        if self._tiles is None:
            raise RendererError("RateSelector.decoded: nothing selected yet")
        th, tw = self._tiles
        return np.frombuffer(self._decoded.read(), np.float32).reshape(6, th, tw).copy()

    def close(self) -> None:
        """Release the GPU objects (and the context when the selector made it; a borrowed context released first
        took them with it). From a thread where the context cannot be made current (another thread holds it) a
        borrowed context's objects are not freed: a warning says so, and the selector is closed all the same; a
        context the selector made is released from any thread, and its objects go with it."""
        live = not is_released(self.ctx)
        objects = (self._texture, self._decoded, self._raw, self._engine, self._program, self._budget_program,
                   self._budget, self._current)
        free = live and any(obj is not None for obj in objects)
        if free:
            self.ctx.__enter__()  # (its objects are freed in its own context)
            # (refused in silence where another thread holds it: freed here, they were the same names in the context
            # current in this thread, an engine's own buffers and textures deleted under it)
            free = self._current is None or self._current.holds()
            if not free and not self._own_ctx:
                warn_not_freed("an rtp RateSelector", "compute programs, buffers and rate texture",
                               "Close it in the thread where its context is current, or release the context there "
                               "first (ctx.__exit__(None, None, None))")
        for obj in objects:
            if obj is not None and free:
                obj.release()
        self._texture = self._decoded = self._raw = self._engine = self._program = None
        self._budget_program = self._budget = self._current = None
        self._tiles = None
        if self._own_ctx and live:
            self.ctx.release()
            self._own_ctx = False  # closing twice releases nothing twice

    def __del__(self) -> None:
        # moderngl frees nothing a Python object held (its objects live until released): a selector dropped unclosed
        # kept its programs, buffers and textures, and the headless context it made itself with them (about 4 MB
        # each on llvmpipe: an engine that made one per level load grew by that every level), and said nothing.
        # A context it made is its alone: released here with everything in it (the context current, the engine's,
        # is not touched). In a borrowed one its objects stay until that context goes, as an unclosed Adapter's do:
        # the engine's context need not be current when Python collects the selector, to free them in.
        made = self.__dict__
        if made.get("_program") is None:  # (closed; or a constructor that failed, which closed what it made)
            return
        ctx = made.get("ctx")
        if ctx is None or is_released(ctx):  # (its objects went with the context)
            return
        own = bool(made.get("_own_ctx"))
        if own:
            try:
                ctx.release()
            except Exception:  # (the interpreter going down: nothing to do)
                return
            self._own_ctx = False
        warnings.warn("an unclosed rtp RateSelector " + (
            "released the headless GL context it made when it was collected" if own else
            "keeps its compute programs, buffers and rate texture in the borrowed GL context until the context goes")
            + ": close() it, or use it in a with block", ResourceWarning, stacklevel=2)

    def __enter__(self) -> RateSelector:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
