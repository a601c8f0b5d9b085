"""``rtp evaluate``: a model's prediction quality and rate decisions on a dataset, next to the baselines.

The model runs through :func:`rtp.sdk.load` exactly as an engine runs it. Two tables come out
(docs/evaluation.md defines every column):

* **quality**: the paper's prediction-quality columns (R², MAE, MAE of underestimation, sigma of
  the absolute error) in the model's transformed space, plus the share of underestimated tiles,
  the MAE in metric units and Spearman's rank correlation; per scene and for all scenes, on all,
  seen and unseen tiles; for the model (with and without its safety margin) and for Yang 2019's
  estimate (a different quantity unless the metric is JNYang).
* **decisions**: each method's shading rates at its threshold, judged by the true error of the
  chosen rate at the model's threshold: the share of tiles whose rate fails it and the shading
  work saved; for the model, the oracle (true targets), Yang 2019 and FidelityFX.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import reprlib
import shlex
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rtp import sdk
from rtp.capture import DatasetError, TargetError, TargetStore
from rtp.sdk import PREDICTED_RATES, RATE_CODES, ParameterError, select_rates, work_saved

from ._baselines import FFX_CUTOFF, YANG_THRESHOLD, FidelityFX, Yang2019, as_real
from ._scores import real_values, scores

__all__ = ["DEFAULT_UNSEEN_FRACTION", "SPLITS", "EvaluationReport", "check_evaluation", "evaluate", "failing_tiles",
           "spearman", "tile_unseen_share", "write_reports"]

log = logging.getLogger("rtp.evaluate")

#: A tile counts as unseen when more than this share of its pixels is unseen.
DEFAULT_UNSEEN_FRACTION = 0.5
#: Tile subsets every score is reported on.
SPLITS = ("all", "seen", "unseen")
ALL_SCENES = "all scenes"


def tile_unseen_share(seen: np.ndarray, tile: int) -> np.ndarray:
    """Share of unseen pixels per tile, ``1 - mean(seen)`` over the pixels each tile holds:
    ``(H, W)`` in [0, 1] -> ``(ceil(H/tile), ceil(W/tile))`` float64."""
    shape: tuple[int, ...] = tuple(np.shape(seen))
    s = real_values(seen, "seen").reshape(shape)
    if len(shape) != 2:  # (a (1, H, W) plane was numpy's "too many values to unpack")
        raise sdk.InputShapeError(f"seen: expected an (H, W) mask, got shape {shape}", shape, "(H, W)")
    h, w = shape
    th, tw = sdk.tile_grid(h, w, tile)
    ph, pw = sdk.padded_size(h, w, tile)
    num = np.pad(s, ((0, ph - h), (0, pw - w))).reshape(th, tile, tw, tile).sum(axis=(1, 3))
    den = np.outer(sdk.tile_extents(h, tile), sdk.tile_extents(w, tile))  # the pixels each tile holds
    return 1.0 - num / den


def _ranks(a: np.ndarray) -> np.ndarray:
    order = np.argsort(a, kind="mergesort")
    r = np.empty(a.size, np.float64)
    r[order] = np.arange(a.size, dtype=np.float64)
    _, inv, counts = np.unique(a, return_inverse=True, return_counts=True)
    return (np.bincount(inv, weights=r) / counts)[inv]  # ties share their mean rank


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman's rank correlation of two equally long arrays (finite pairs only; ties get mean
    ranks); NaN when either side is constant or fewer than two pairs remain."""
    a, b = real_values(x, "x"), real_values(y, "y")
    if a.shape != b.shape:
        raise sdk.InputShapeError(f"x and y differ in size: {a.size} vs {b.size}", a.shape, str(b.shape))
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    if a.size < 2:
        return float("nan")
    ra, rb = _ranks(a), _ranks(b)
    ra, rb = ra - ra.mean(), rb - rb.mean()
    den = math.sqrt(float((ra * ra).sum() * (rb * rb).sum()))
    return float((ra * rb).sum() / den) if den > 0 else float("nan")


@dataclass
class EvaluationReport:
    """What :func:`evaluate` measured. ``quality`` and ``decisions`` are lists of flat rows (dicts);
    :meth:`to_dict` is what the JSON file holds."""

    model: dict[str, Any]
    data: str
    samples: int
    scenes: dict[str, int]
    unseen_fraction: float
    rates: list[str]
    threshold: float
    #: Per scene: "train" or "validation" when the model's provenance lists it so, else "new".
    scene_roles: dict[str, str] = field(default_factory=dict)
    quality: list[dict[str, Any]] = field(default_factory=list)
    decisions: list[dict[str, Any]] = field(default_factory=list)
    baselines: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: Threshold sweeps over all tiles: rows {method, parameter, fail_share, work_saved}.
    sweep: list[dict[str, Any]] = field(default_factory=list)
    #: Per method, the work it saves when its parameter is set to fail as often as the model does.
    matched: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    plots: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return _json_clean(dataclasses.asdict(self))

    def row(self, table: str, method: str, scene: str | None = None, split: str = "all") -> dict[str, Any]:
        """One row of ``quality`` or ``decisions``; ``scene`` defaults to all scenes together (the
        only scene when there is one)."""
        if scene is None:
            scene = ALL_SCENES if len(self.scenes) > 1 else next(iter(self.scenes))
        for r in getattr(self, table):
            if r["method"] == method and r["scene"] == scene and r["split"] == split:
                return r
        raise KeyError(f"no {table} row for {method}/{scene}/{split}")

    # -- rendering ----------------------------------------------------------------------------
    def _quality_table(self, markdown: bool, render: Callable[[str], str] | None = None) -> list[str]:
        head = ["scene", "split", "method", "n", "R² %", "MAE", "MAE under.", "σ MAE", "under %",
                f"MAE [{self.model['metric']}]", "Spearman"]
        rows = [
            [r["scene"], r["split"], r["method"], str(r["n"]), _pct(r["r2"]), _e(r["mae"]), _e(r["mae_under"]),
             _e(r["sigma"]), _pct(r["under_share"]), _e(r["mae_metric"]), _f(r["spearman"])]
            for r in self.quality
        ]
        return _table(head, rows, markdown, render)

    def _decision_table(self, markdown: bool, render: Callable[[str], str] | None = None) -> list[str]:
        head = ["scene", "split", "method", "threshold", "n", "fails %", "work saved %", "rates (1x1/1x2/2x1/2x2/2x4/4x2/4x4 %)"]
        rows = [
            [r["scene"], r["split"], r["method"], f"{r['threshold']:g}", str(r["n"]), _pct(r["fail_share"]),
             _pct(r["work_saved"]), _shares(r["rate_shares"])]
            for r in self.decisions
        ]
        return _table(head, rows, markdown, render)

    def _header(self) -> list[str]:
        m = self.model
        return [
            f"model {m['path']}: {m['metric']}, tile {m['tile_size']}" + _tiles_text(m['tile_size'], m.get('model_tile_size'))
            + f", transform {_transform_text(m['transform'])}, "
            f"safety {m['safety']:g}, "
            f"outputs {','.join(m['outputs'])}",
            f"data {self.data}: {self.samples} samples, scenes "
            + ", ".join(f"{s} ({n}, {self.scene_roles.get(s, 'new')})" for s, n in self.scenes.items())
            + f"; a tile is unseen when > {100 * self.unseen_fraction:g}% of its pixels are",
            f"quality on rates {','.join(self.rates)} in transformed space; decisions judged at {m['metric']} "
            f"threshold {self.threshold:g}",
        ]

    def table(self, render: Callable[[str], str] | None = None) -> str:
        """Both tables as aligned plain text, for a terminal. ``render``: each cell as the terminal will show it,
        measured so (``rtp evaluate``'s: "R² %" as "R^2 %" on a console that is not UTF-8, whose columns were measured
        on the characters before and shifted)."""
        lines = self._header() + ["", "Prediction quality"] + self._quality_table(False, render)
        lines += ["", "VRS decisions"] + self._decision_table(False, render)
        lines += [""] + [f"note: {n}" for n in self.notes]
        return "\n".join(lines)

    def to_markdown(self, where: str | os.PathLike[str] | None = None) -> str:
        """The report as markdown; ``where``: the folder the file goes in, which its plot links are relative to
        (default: beside the plots, as ``rtp evaluate --out`` writes them)."""
        lines = [f"# Evaluation of {Path(self.model['path']).name}", ""] + [f"- {h}" for h in self._header()]
        lines += ["", "## Prediction quality", ""] + self._quality_table(True)
        lines += ["", "## VRS decisions", ""] + self._decision_table(True)
        if self.matched:
            lines += ["", "## At matched quality", "",
                      "Each method's parameter swept over all tiles of all scenes; the most work it saves failing at "
                      f"most as often as the model at its threshold {self.threshold:g}, the decision table's (each sweep "
                      "point interpolated linearly towards the next one that fails more, as `evaluate.saved_at` reads a "
                      "sweep).", "",
                      "| method | fails % | work saved % | parameter |", "|---|---|---|---|"]
            lines += [f"| {m['method']} | {_pct(m['fail_share'])} | {_pct(m['work_saved'])} | {m['parameter']} |"
                      for m in self.matched]
        if self.baselines:
            lines += ["", "## Baseline parameters", ""]
            lines += [f"- `{k}`: " + ", ".join(f"{a}={b}" for a, b in v.items()) for k, v in self.baselines.items()]
        if self.notes:
            lines += ["", "## Notes", ""] + [f"- {n}" for n in self.notes]
        if self.plots:
            from urllib.parse import quote  # (a space in a model's file name broke the image link)

            lines += ["", "## Plots", ""] + [f"![{Path(p).stem}]({quote(_link(p, where))})" for p in self.plots]
        return "\n".join(lines) + "\n"

    def write(self, out_dir: str | os.PathLike[str], stem: str = "evaluation") -> list[Path]:
        """Write ``<stem>.md`` and ``<stem>.json`` into ``out_dir`` as :func:`write_reports` does for
        this one report (what ``rtp evaluate MODEL --out DIR`` writes); returns their paths."""
        return write_reports([self], out_dir, stem)


def write_reports(reports: Sequence[EvaluationReport], out_dir: str | os.PathLike[str],
                  stem: str = "evaluation") -> list[Path]:
    """Write ``<stem>.md`` (each report's markdown in turn) and ``<stem>.json`` (a list of their
    ``to_dict()``: what ``rtp evaluate --out`` writes and ``bench/report.py`` reads) into ``out_dir``,
    each atomically, and neither where either's text fails (an interrupted write leaves the previous files);
    returns their paths. The plots the ``<stem>.json`` they replace listed in ``out_dir`` and these reports do
    not are removed (another evaluation's, which no report shows any more); no other file."""
    from rtp.sdk.files import atomic_output

    reports = list(reports)
    if not reports or not all(isinstance(r, EvaluationReport) for r in reports):
        raise ParameterError(f"reports: expected one or more EvaluationReport, got {reprlib.repr(reports)}", "reports")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{stem}.md", out / f"{stem}.json"]
    before = _listed_plots(paths[1])
    # both texts before either file (a report whose JSON failed, a NaN say, left the new .md beside the old .json:
    # two evaluations' halves), and the two renames back to back, the .json (what tools read) last
    texts = ["\n".join(r.to_markdown(out) for r in reports),
             json.dumps([r.to_dict() for r in reports], indent=1, allow_nan=False)]
    with atomic_output(paths[1]) as js_tmp, atomic_output(paths[0]) as md_tmp:  # (the inner one's rename first)
        md_tmp.write_text(texts[0], encoding="utf-8")
        js_tmp.write_text(texts[1], encoding="utf-8")
    # (`rtp evaluate psnr --out F` into jnyang's folder left jnyang_*.png beside psnr's report)
    gone = sorted(before - {Path(p).name for r in reports for p in r.plots})
    for name in gone:
        (out / name).unlink(missing_ok=True)
    if gone:
        log.info("%s: removed %s, the plots of the evaluation this one replaced", out, ", ".join(gone))
    return paths


def _link(plot: str, where: str | os.PathLike[str] | None) -> str:
    """A plot's link in a report written into ``where``: its name where it lies there (or ``where`` is not known),
    else its path relative to ``where`` (plots drawn into another ``plots_dir`` were linked by name: broken links)."""
    path = Path(plot)
    if where is None or path.parent.resolve() == Path(where).resolve():
        return path.name
    try:
        return Path(os.path.relpath(path.resolve(), Path(where).resolve())).as_posix()
    except ValueError:  # (another drive, on Windows)
        return path.resolve().as_posix()


#: The endings of the plot files :func:`evaluate` writes (``<name>_heatmaps.png``, ...).
_PLOT_ENDINGS = ("_heatmaps.png", "_scatter.png", "_rates.png")


def _listed_plots(report: Path) -> set[str]:
    """The names of the plots an evaluation.json lists that lie beside it, of the names evaluate gives them:
    those rtp wrote there (none where it is missing or unreadable)."""
    try:
        entries = json.loads(report.read_text(encoding="utf-8"))
        listed = {Path(str(p)).name for e in entries for p in e.get("plots") or ()}
    except (OSError, UnicodeDecodeError, ValueError, RecursionError, TypeError, AttributeError):
        return set()
    return {n for n in listed if n.endswith(_PLOT_ENDINGS) and (report.parent / n).is_file()}


def _tiles_text(tile: int, own: int | None) -> str:
    """How the hardware tiles judged relate to the model's own: coarser ones pool the model's (the worst of those
    each covers), finer ones split them (each takes its model tile's values)."""
    if own is None or own == tile:
        return ""
    return f" (pooled from the model's {own})" if tile > own else f" (each its part of the model's {own})"


def _transform_text(t: dict[str, Any]) -> str:
    params = ", ".join(f"{k}={v:.4g}" for k, v in t.items() if k != "type")
    return f"{t['type']} ({params})"


def _json_clean(v: Any) -> Any:
    if isinstance(v, dict):
        return {str(k): _json_clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_clean(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


def _e(v: float) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.2e}"


def _f(v: float) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{v:.3f}"


def _pct(v: float) -> str:
    return "-" if v is None or not math.isfinite(v) else f"{100 * v:.1f}"


def _shares(shares: dict[str, float | None]) -> str:
    """The rates column: each rate's share of the tiles in percent, ``1x1/1x2/...``; "-" where there are no tiles
    (an empty split, such as the unseen tiles of frames seen whole: it read "nan/nan/nan/nan/nan/nan/nan")."""
    values = [shares.get(k) for k in sdk.ALL_RATES]
    if any(v is None or not math.isfinite(v) for v in values):
        return "-"
    return "/".join(f"{100 * v:.0f}" for v in values if v is not None)


def _table(head: list[str], rows: list[list[str]], markdown: bool,
           render: Callable[[str], str] | None = None) -> list[str]:
    if render is not None and not markdown:  # (the cells as they will be shown, before they are measured)
        head, rows = [render(c) for c in head], [[render(c) for c in r] for r in rows]
    if markdown:
        return ["| " + " | ".join(head) + " |", "|" + "|".join("---" for _ in head) + "|"] + [
            "| " + " | ".join(r) + " |" for r in rows
        ]
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(head)]
    fmt = lambda cells: "  ".join(c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))  # noqa: E731
    return [fmt(head)] + [fmt(r) for r in rows]


# -- accumulation ---------------------------------------------------------------------------------


class _Quality:
    """Per-tile values of one method in one scene, flattened over the scored rates."""

    def __init__(self) -> None:
        self.p: list[np.ndarray] = []
        self.g: list[np.ndarray] = []
        self.pm: list[np.ndarray] = []
        self.gm: list[np.ndarray] = []
        self.unseen: list[np.ndarray] = []

    def add(self, p: np.ndarray, g: np.ndarray, pm: np.ndarray, gm: np.ndarray, unseen: np.ndarray) -> None:
        self.p.append(p.ravel())
        self.g.append(g.ravel())
        self.pm.append(pm.ravel())
        self.gm.append(gm.ravel())
        self.unseen.append(np.broadcast_to(unseen, p.shape).ravel())

    def merged(self) -> tuple[np.ndarray, ...]:
        return tuple(np.concatenate(x) if x else np.zeros(0) for x in (self.p, self.g, self.pm, self.gm, self.unseen))


class _Decisions:
    """Per-tile rate codes of one method in one scene, whether each fails, whether it is unseen and the pixels it
    holds (a partial tile at the frame's edge its real ones: the work saved is a share of the frame's pixels)."""

    def __init__(self) -> None:
        self.codes: list[np.ndarray] = []
        self.fail: list[np.ndarray] = []
        self.unseen: list[np.ndarray] = []
        self.pixels: list[np.ndarray] = []

    def add(self, codes: np.ndarray, fail: np.ndarray, unseen: np.ndarray, pixels: np.ndarray) -> None:
        self.codes.append(codes.ravel())
        self.fail.append(fail.ravel())
        self.unseen.append(unseen.ravel())
        self.pixels.append(np.broadcast_to(pixels, codes.shape).ravel())

    def merged(self) -> tuple[np.ndarray, ...]:
        return tuple(np.concatenate(x) if x else np.zeros(0) for x in (self.codes, self.fail, self.unseen, self.pixels))


_SAVED = np.zeros(16)
for _r in sdk.ALL_RATES:
    _SAVED[RATE_CODES[_r]] = work_saved(_r)


def failing_tiles(codes: np.ndarray, truth: np.ndarray, threshold: float, higher_is_better: bool) -> np.ndarray:
    """Whether each tile's chosen rate fails the threshold by the true error (1x1 never fails). ``codes``: uint8
    rate codes, a tile each; ``truth``: ``(6, *codes.shape)``, each predicted rate's true value. ``threshold`` is
    one a selection takes (``sdk.check_threshold``), ``higher_is_better`` True or False, else a ParameterError."""
    # (a NaN threshold failed every reduced rate, and higher_is_better="False" judged an error as a PSNR, silently)
    threshold = sdk.check_threshold(threshold, higher_is_better)
    codes, truth = np.asarray(codes), np.asarray(truth)
    if truth.shape != (len(PREDICTED_RATES), *codes.shape):
        raise sdk.InputShapeError(f"truth: expected shape {(len(PREDICTED_RATES), *codes.shape)} (each predicted rate's "
                                  f"value on the codes' tiles), got {truth.shape}", truth.shape, "(6, th, tw)")
    if codes.size and not np.isin(codes, list(RATE_CODES.values())).all():
        raise sdk.ParameterError(f"codes: expected rate codes ({', '.join(map(str, sorted(RATE_CODES.values())))}), "
                                 f"got {sorted(set(np.unique(codes).tolist()) - set(RATE_CODES.values()))[:4]}", "codes")
    out = np.zeros(codes.shape, bool)
    for i, r in enumerate(PREDICTED_RATES):
        m = codes == RATE_CODES[r]
        if m.any():
            e = truth[i][m]
            out[m] = ~(e > threshold) if higher_is_better else ~(e < threshold)
    return out


#: For each predicted rate (``PREDICTED_RATES`` order, finer before coarser) the indices of the other
#: rates whose blocks its blocks contain, those no wider and no taller: 2x2's contain 1x2's and 2x1's,
#: 2x4's and 4x2's those and 2x2's, 4x4's all five.
CONTAINED_RATES: tuple[tuple[int, ...], ...] = tuple(
    tuple(j for j, q in enumerate(PREDICTED_RATES)
          if q != r and sdk.rate_size(q)[0] <= sdk.rate_size(r)[0] and sdk.rate_size(q)[1] <= sdk.rate_size(r)[1])
    for r in PREDICTED_RATES)


def monotone_over_rates(values: np.ndarray, higher_is_better: bool = False) -> np.ndarray:
    """Per-tile values of the six rates (``(..., 6, th, tw)``) made monotone over the rates: each rate's
    value the worst of its own and those of the rates its blocks contain (:data:`CONTAINED_RATES`).
    The true error of a coarser rate can be the better one (its one sample per block lands on a
    better pixel than the finer rate's); a predictor that orders the rates cannot know that luck, so
    the oracle on the truth made so (``rtp play``'s ``oracle-monotone``) is what such a predictor
    can reach. A copy; finer rates come first, so each envelope is final before a coarser one reads it."""
    values = as_real(values, "values")
    if values.ndim < 3 or values.shape[-3] != len(PREDICTED_RATES):
        raise sdk.InputShapeError(f"expected values with {len(PREDICTED_RATES)} rate channels on axis -3, got shape "
                                  f"{values.shape}", tuple(values.shape), "(..., 6, th, tw)")
    out = values.copy()
    worst = np.minimum if higher_is_better else np.maximum
    for i, below in enumerate(CONTAINED_RATES):
        for j in below:
            worst(out[..., i, :, :], out[..., j, :, :], out=out[..., i, :, :])
    return out


def tile_pixels(size: tuple[int, int], tile: int) -> np.ndarray:
    """The pixels each tile of a frame of ``size = (H, W)`` holds, ``(th, tw)`` float64: partial tiles at the
    frame's right and bottom edges their real ones (as ``sdk.work_saved(codes, size, tile)`` weighs them)."""
    h, w = size
    return np.outer(sdk.tile_extents(h, tile), sdk.tile_extents(w, tile)).astype(np.float64)


def _split_masks(unseen: np.ndarray) -> dict[str, np.ndarray]:
    return {"all": np.ones(unseen.shape, bool), "seen": ~unseen, "unseen": unseen}


# -- the evaluation -------------------------------------------------------------------------------


def evaluate(
    model: str | os.PathLike[str],
    data: str | os.PathLike[str],
    *,
    scenes: Sequence[str] | None = None,
    metadata: Any = None,
    threshold: float | None = None,
    unseen_fraction: float = DEFAULT_UNSEEN_FRACTION,
    baselines: bool = True,
    yang: Yang2019 | None = None,
    fidelityfx: FidelityFX | None = None,
    max_samples: int | None = None,
    plots_dir: str | os.PathLike[str] | None = None,
    plot_sample: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    sweep: bool = True,
    tile_size: int | None = None,
    plot_name: str | None = None,
    palette: str = "paper",
) -> EvaluationReport:
    """Evaluate an ONNX model on a dataset with targets (``rtp targets``) for its metric and tile.

    ``scenes`` restricts the samples (``meta["scene"]``; one name or a list; None or an empty list: all);
    ``threshold`` (metric units) replaces the model's ``default_threshold`` for the decision table;
    ``unseen_fraction`` is the seen/unseen rule. ``yang`` / ``fidelityfx`` replace the default baselines (built
    at the model's tile size; Yang's sensitivity is the model's threshold when the metric is JNYang, else its own 0.25,
    and its environment luminance the JNYang model's ``weber_l``, else its own 0.02); a ``Yang2019`` given is one of
    its two variants (``unseen="as_is"`` or ``"full"``), the other built from its parameters, so that both are
    reported, the quality table scoring the ``as_is`` one.
    ``sweep`` also sweeps every method's threshold (cutoff) to compare the work saved at the
    model's failure rate (``report.matched``). ``plots_dir`` writes the figures of
    :mod:`rtp.evaluate.plots` for ``plot_sample`` (default: the first sample).
    ``progress(done, total)`` is called after each sample. ``tile_size`` evaluates the model on
    the hardware's tiles where they differ from its own (``sdk.load(tile_size=...)``: an 8-pixel model
    on NVIDIA's 16-pixel tiles, each hardware tile taking the worst of its model tiles; a 16-pixel model
    on AMD's and Intel's 8-pixel tiles, each taking its model tile's values), against targets of that
    tile size; the baselines decide on those tiles.

    The steps: load the model and the samples, build the baselines, take in each sample
    (:class:`_Run`: predictions and targets, quality values, every method's rates, the sweeps),
    then assemble the report and write the plots, named ``<plot_name>_heatmaps.png`` and so on (default: the
    model file's stem; two models whose files share a stem need names of their own in one ``plots_dir``).
    ``palette``: the rate overlays' colours (``<plot_name>_rates.png``), ``"paper"`` or ``"cvd"``, told apart under
    colour-vision deficiency (:data:`rtp.sdk.OVERLAY_PALETTES`).
    """
    if isinstance(unseen_fraction, bool) or not isinstance(unseen_fraction, (int, float, np.number)) \
            or not 0.0 <= unseen_fraction < 1.0:
        raise ParameterError(f"unseen_fraction must be a share in [0, 1), got {unseen_fraction!r}", "unseen_fraction")
    _check_max_samples(max_samples)
    scenes = _scene_names(scenes)
    for key, flag in (("baselines", baselines), ("sweep", sweep)):
        if not isinstance(flag, bool):  # ("no" is a true string)
            raise ParameterError(f"{key} must be True or False, got {flag!r}", key)
    if plot_sample is not None and not isinstance(plot_sample, str):
        raise ParameterError(f"plot_sample must be None or a sample id, got {plot_sample!r}", "plot_sample")
    if plot_name is not None and (not isinstance(plot_name, str) or not plot_name or plot_name in (".", "..")
                                  or any(c in plot_name for c in "/\\\0")):
        raise ParameterError(f"plot_name must be None (the model file's stem) or a file name without a folder, got "
                             f"{plot_name!r}", "plot_name")
    from .plots import rate_legend

    rate_legend(palette)  # (an unknown palette refused before the model is loaded and the samples evaluated)
    predictor, meta, thr, store, samples = _prepare(model, data, scenes, metadata, threshold, max_samples, tile_size)
    mismatch = _targets_mismatch(meta, store)
    if mismatch:
        log.warning("%s: %s", predictor.path, mismatch)
    selectors = _baselines(meta, thr, unseen_fraction, yang, fidelityfx) if baselines else {}
    # (by its kind, not its name: a Yang2019 given under another name had no quality rows)
    yang_scored = None if meta.higher_is_better else _yang_variants(selectors)[0]
    run = _Run(predictor, store, thr, unseen_fraction, selectors, yang_scored, sweep)
    plot_id = _plot_sample_id(samples, plot_sample)
    plot_data: dict[str, Any] | None = None
    for n, sample in enumerate(samples, 1):
        outcome = run.add(sample)
        if plots_dir is not None and sample.id == plot_id:
            plot_data = outcome
        if progress:
            progress(n, len(samples))
    report = run.report(data)
    if plots_dir is not None and plot_data is not None:
        report.plots = run.plots(Path(plots_dir), plot_data, plot_name, palette)
    return report


def check_evaluation(
    model: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    data: str | os.PathLike[str],
    *,
    scenes: Sequence[str] | None = None,
    metadata: Any = None,
    threshold: float | None = None,
    tile_size: int | None = None,
    max_samples: int | None = None,
) -> None:
    """What :func:`evaluate` would refuse before its first sample, without evaluating: the model
    (``sdk.load``), the threshold in its metric's units, the dataset, its targets for the model's
    metric and tile (on every sample to evaluate: the ``scenes``, the first ``max_samples`` of them), the
    ``scenes``. ``model``: one model, or a list of them, each checked so; the targets every model's metric lacks
    are named in one :class:`~rtp.capture.TargetError` with the one ``rtp targets`` command that computes them all
    (it named the first model's only: the next metric was learnt of on the next try). ``rtp evaluate`` checks every
    model it is given so, before the first is evaluated (a dataset without the last model's targets was refused
    only after the others had run)."""
    models: list[Any] = list(model) if isinstance(model, (list, tuple)) else [model]
    if not models:
        raise ParameterError("model: expected a model or a list of one or more, got an empty list", "model")
    _check_max_samples(max_samples)
    lacking: list[TargetError] = []
    for m in models:
        try:
            _prepare(m, data, scenes, metadata, threshold, max_samples, tile_size)
        except TargetError as err:  # (the next models' too, before saying what to compute)
            if not isinstance(getattr(err, "lack", None), _Lack):
                raise
            lacking.append(err)
    if lacking:
        raise _combined(data, lacking)


def _check_max_samples(max_samples: object) -> None:
    if max_samples is not None and (isinstance(max_samples, bool) or not isinstance(max_samples, (int, np.integer))
                                    or max_samples < 1):
        raise ParameterError(f"max_samples must be None (all) or an integer >= 1, got {max_samples!r}", "max_samples")


def _targets_mismatch(meta: sdk.ModelMetadata, store: TargetStore) -> str:
    """What makes the dataset's targets another quantity than the one the model predicts: the environment luminance
    l of a Weber-corrected metric (JNYang, JNFLIP) the model was trained with (``metadata.weber_l``) against the one
    its targets were computed with (``rtp targets --weber-l``); a plugin metric's definition (its ``params`` and
    pooling, which the model's ``provenance.target_parameters`` records of its training targets) against the one
    the dataset's targets manifest records; "" where they agree or either is not recorded."""
    declared = store.metrics.get(meta.metric)
    trained = meta.to_dict()["provenance"].get("target_parameters") if meta.metric not in sdk.METRICS else None
    if isinstance(declared, dict) and isinstance(trained, dict) and "plugin" in trained and "plugin" in declared:
        # (a model of the plugin's version 1 was scored against version 2's targets in silence)
        keys = [k for k in ("plugin", "pooling") if k in trained and k in declared]
        model_def, data_def = {k: trained[k] for k in keys}, {k: declared[k] for k in keys}
        if model_def != data_def:
            return (f"the model predicts the plugin metric {meta.metric} as defined by {model_def}, and the targets "
                    f"it is judged against were computed with {data_def}: another definition, so its scores and "
                    f"failing tiles are not its own (compute {meta.metric} targets with the model's definition "
                    f"installed in a copy of the dataset: `rtp targets COPY --metrics {meta.metric}`)")
    targets_l = declared.get("weber_l") if isinstance(declared, dict) else None
    if meta.weber_l is None or isinstance(targets_l, bool) or not isinstance(targets_l, (int, float)):
        return ""
    if math.isclose(float(meta.weber_l), float(targets_l), rel_tol=1e-6):
        return ""
    return (f"the model predicts {meta.metric} at environment luminance l = {meta.weber_l:g}, and the targets it is "
            f"judged against were computed at l = {targets_l:g}: another quantity, so its scores and failing tiles "
            f"are not its own (compute targets at l = {meta.weber_l:g} in a copy of the dataset: `rtp targets COPY "
            f"--metrics {meta.metric} --weber-l {meta.weber_l:g}`)")


def _scene_names(scenes: object) -> list[str] | None:
    """``scenes`` as :func:`evaluate` and :func:`check_evaluation` take it: None (all), one name (not its letters)
    or a list of names; else a :class:`ParameterError`."""
    scenes = [scenes] if isinstance(scenes, str) else scenes
    if scenes is not None and (not isinstance(scenes, (list, tuple, set, frozenset))
                               or not all(isinstance(x, str) for x in scenes)):
        raise ParameterError(f"scenes must be None (all), a scene name or a list of them, got {scenes!r}", "scenes")
    return None if scenes is None else list(scenes)


def _prepare(model: str | os.PathLike[str], data: str | os.PathLike[str], scenes: Sequence[str] | None, metadata: Any,
             threshold: float | None, max_samples: int | None, tile_size: int | None,
             ) -> tuple[sdk.ShadingRatePredictor, sdk.ModelMetadata, float, TargetStore, list[Any]]:
    """The predictor, its metadata on its (hardware) tiles, the decision threshold, the target store and
    the samples to evaluate."""
    scenes = _scene_names(scenes)
    predictor = sdk.load(model, metadata=metadata, tile_size=tile_size)
    # the metadata as evaluated: on the predictor's (hardware) tiles
    meta = dataclasses.replace(predictor.metadata, tile_size=predictor.tile_size)
    thr = meta.default_threshold if threshold is None else sdk.check_threshold(threshold, meta.higher_is_better)
    # (the model's own tile, where tile_size asked for other hardware tiles: None where it did not)
    model_tile = None if tile_size is None else predictor.metadata.tile_size
    store, samples = _load_samples(data, meta, scenes, max_samples, model_tile)
    return predictor, meta, thr, store, samples


def _load_samples(
    data: str | os.PathLike[str], meta: sdk.ModelMetadata, scenes: Sequence[str] | None, max_samples: int | None,
    model_tile: int | None = None,
) -> tuple[TargetStore, list[Any]]:
    """The dataset's target store and the samples to evaluate, after checking that the targets
    fit the model (metric, tile). ``meta``: on the tiles evaluated; ``model_tile``: the model's own, where those are
    hardware tiles ``tile_size`` asked for (None: the model's)."""
    from rtp.capture import DatasetReader

    reader = DatasetReader(data)
    store = TargetStore(data)
    if meta.metric not in store.metrics:
        raise _lacking(data, [meta.metric], [f"no {meta.metric} targets"], list(store.metrics))
    if meta.tile_size % store.base_tile:
        base = store.base_tile
        # (the hardware tile of tile_size / --tile-size was called "the model's tile", which it is not)
        whose = f"the model's tile {meta.tile_size}" if model_tile is None else \
            f"the hardware tile {meta.tile_size} asked for (tile_size, `rtp evaluate --tile-size`)"
        own = "" if model_tile is None or model_tile % base else f" (the model's own {model_tile} is one)"
        raise TargetError(f"{whose} is not a multiple of the targets' base tile {base} in {data}: their values cannot "
                          f"be pooled to it; evaluate on a multiple of {base}{own}")
    samples = _select_samples([reader[i] for i in list(reader.ids)], data, scenes, max_samples)
    _check_targets(store, samples, meta.metric, data)
    return store, samples


@dataclasses.dataclass(frozen=True)
class _Lack:
    """What a dataset lacks of the targets of the metrics to evaluate, which ``rtp targets DATA --metrics METRICS``
    computes: ``lacks``, each lack in words ("no psnr targets", "2 of the 3 samples ... have no jnyang targets
    (...)"); ``have``, the metrics whose targets it has, where a metric has none at all. Carried by the
    :class:`TargetError` :func:`_lacking` makes (a class of its own would be one more error class to document)."""

    data: str | os.PathLike[str]
    metrics: tuple[str, ...]
    lacks: tuple[str, ...]
    have: tuple[str, ...] | None = None


def _lacking(data: str | os.PathLike[str], metrics: Sequence[str], lacks: Sequence[str],
             have: Sequence[str] | None = None) -> TargetError:
    """The :class:`TargetError` of a :class:`_Lack`, with it as its ``lack`` attribute."""
    lack = _Lack(data, tuple(metrics), tuple(lacks), None if have is None else tuple(have))
    where = f"{data} has " if len(lack.lacks) == 1 and have is not None else \
        f"{data}: " if len(lack.lacks) == 1 else f"{data} lacks the targets of {len(lack.metrics)} metrics: "
    held = "" if have is None else f" (it has {', '.join(have) or 'none'})"
    err = TargetError(f"{where}{'; '.join(lack.lacks)}{held}; run `rtp targets {shlex.quote(str(data))} --metrics "
                      f"{','.join(lack.metrics)}`")
    err.lack = lack  # type: ignore[attr-defined]
    return err


def _combined(data: str | os.PathLike[str], errors: Sequence[TargetError]) -> TargetError:
    """One error for the lacks of several models' metrics (each error of :func:`_lacking`), with the one command
    that computes them all (the error itself where there is one)."""
    if len(errors) == 1:
        return errors[0]
    lacks: list[_Lack] = [e.lack for e in errors]  # type: ignore[attr-defined]
    metrics = list(dict.fromkeys(m for x in lacks for m in x.metrics))  # (two models of one metric: once)
    words = list(dict.fromkeys(w for x in lacks for w in x.lacks))
    have = next((x.have for x in lacks if x.have is not None), None)
    return _lacking(data, metrics, words, have)


def _check_targets(store: TargetStore, samples: list[Any], metric: str, data: str | os.PathLike[str]) -> None:
    """Refuse, before the first sample is evaluated, samples without up-to-date ``metric`` targets (a sample captured
    after ``rtp targets`` ran, or captured again since): the run stopped at the first such sample, after the work on
    the ones before it (in ``rtp evaluate`` with several models, after the models before)."""
    missing = [s.id for s in samples if not store.path(s.id, metric).is_file()]
    stale = [] if missing else [s.id for s in samples if store.stale(s.id, metric)]
    bad = missing or stale
    if bad:
        what = "no" if missing else "outdated (of the sample before it was captured again)"
        raise _lacking(data, [metric], [f"{len(bad)} of the {len(samples)} samples to evaluate have {what} "
                                               f"{metric} targets ({', '.join(map(repr, bad[:3]))}"
                                               f"{', ...' if len(bad) > 3 else ''})"])


def _select_samples(
    samples: list[Any], data: str | os.PathLike[str], scenes: Sequence[str] | None, max_samples: int | None
) -> list[Any]:
    """The samples of ``scenes`` (all when None), the first ``max_samples`` of them; never none."""
    if scenes:
        wanted = set(scenes)
        have = {str(s.meta.get("scene", "?")) for s in samples}
        missing = sorted(wanted - have)
        if missing:
            raise ParameterError(f"scenes: {', '.join(missing)} {'is' if len(missing) == 1 else 'are'} not in {data}; it "
                                 f"holds {', '.join(sorted(have))}", "scenes")
        samples = [s for s in samples if str(s.meta.get("scene", "?")) in wanted]
    if max_samples:
        samples = samples[:max_samples]
    if not samples:
        raise DatasetError(f"no samples to evaluate in {data}")
    return samples


def _baselines(
    meta: sdk.ModelMetadata, thr: float, unseen_fraction: float, yang: Yang2019 | None, fidelityfx: FidelityFX | None
) -> dict[str, Any]:
    """The baseline selectors by name, at the model's tile size: Yang 2019 (and its variant that
    shades unseen tiles fully) and FidelityFX (base and additional rates), or the ones given."""
    tile = meta.tile_size
    y_thr = thr if meta.metric == "jnyang" else YANG_THRESHOLD
    # A JNYang model's environment luminance too: Yang's estimates E / (L + l) are then in the units of the model's
    # threshold and of the targets (l = weber_l); with its own 0.02 a model at another l had them judged in others.
    y_l: dict[str, Any] = {"env_luminance": float(meta.weber_l)} if meta.metric == "jnyang" and meta.weber_l is not None else {}
    # Motion off: the targets are errors of still frames, and a viewpoint pair is a jump, not one
    # frame of motion at 60 Hz, so the baselines' motion terms (which model motion blur hiding
    # error) would only make them look worse than they are.
    for key, given, kind in (("yang", yang, Yang2019), ("fidelityfx", fidelityfx, FidelityFX)):
        if given is not None and not isinstance(given, kind):  # (an AttributeError deep in the run, or none at all)
            raise ParameterError(f"{key}: expected None (the default) or a {kind.__name__}, got {reprlib.repr(given)}",
                                 key)
    yang = yang or Yang2019(tile, threshold=y_thr, unseen_fraction=unseen_fraction, motion=False, **y_l)
    # Both of its variants, built from the one given, whichever it is: as RT-Percept's (unseen tiles as they are:
    # the row 'yang2019', whose estimates the quality table scores) and shading unseen tiles at 1x1. (Given
    # Yang2019(unseen="full"), the report had no Yang quality rows and no Yang notes: both looked for 'yang2019'.)
    kw = {k: v for k, v in yang.params().items() if k not in ("luma", "tile_size", "unseen")}
    other = Yang2019(yang.tile_size, **kw, unseen="full" if yang.unseen == "as_is" else "as_is")
    yang, yang_full = (yang, other) if yang.unseen == "as_is" else (other, yang)
    if fidelityfx is None:
        ffx_tile = tile if tile in (8, 16, 32) else None
        ffx = ([FidelityFX(ffx_tile, motion_factor=0.0), FidelityFX(ffx_tile, motion_factor=0.0, additional_rates=True)]
               if ffx_tile else [])
        if not ffx_tile:
            log.warning("FidelityFX supports tiles of 8, 16 and 32 pixels; the model's %d-pixel tiles leave it out", tile)
    else:
        ffx = [fidelityfx]
    selectors: dict[str, Any] = {}
    every: list[Yang2019 | FidelityFX] = [yang, yang_full, *ffx]
    for sel in every:
        if sel.tile_size != tile:
            raise ParameterError(f"baseline {sel.name} uses {sel.tile_size}-pixel tiles, the model {tile}")
        selectors[sel.name] = sel
    return selectors


def _plot_sample_id(samples: list[Any], plot_sample: str | None) -> str:
    """The id of the sample the plots show: ``plot_sample``, by default the first sample."""
    plot_id = plot_sample or samples[0].id
    if plot_sample and plot_sample not in {s.id for s in samples}:
        ids = [s.id for s in samples]
        raise ParameterError(f"plot_sample: {plot_sample!r} is not among the evaluated samples ({', '.join(ids[:3])}"
                             f"{f', ... {len(ids)} in all' if len(ids) > 3 else ''})", "plot_sample")
    return plot_id


class _Sweep:
    """Each method's threshold (FidelityFX: cutoff) swept over a grid: per (method, parameter), the
    tiles whose rate fails the model's threshold, the work saved and the tiles counted."""

    def __init__(self, thr: float, hib: bool, selectors: dict[str, Any],
                 factors: tuple[float, ...] | None = None) -> None:
        self.thr, self.hib, self.selectors, self.factors = thr, hib, selectors, factors
        steps = [2.0 ** (k / 2) for k in range(-8, 9)]
        # Each grid is clipped to the thresholds a selection takes (sdk.check_threshold), once each: a valid
        # threshold near the range's end (--threshold 1e6) swept past it, refused as if the user had given
        # 1.41421e+06, and at 0 every multiple of it was the same point.
        lo = -sdk.MAX_THRESHOLD if hib else 0.0

        def grid(values: Iterable[float], low: float = lo) -> list[float]:
            return list(dict.fromkeys(min(sdk.MAX_THRESHOLD, max(low, v)) for v in values))

        self.model_grid = grid([thr + 2.0 * k for k in range(-8, 9)] if hib else [thr * f for f in steps])
        # The baselines' grids reach 1/256 of their defaults, so that every method that can fail as
        # rarely as 1% of the tiles shows it (a black, unseen reprojection looks flat at any value).
        low = [2.0 ** (k / 2) for k in range(-16, 9)]
        self.yang_grids = {name: grid((sel.threshold * f for f in low), 0.0) for name, sel in selectors.items()
                           if isinstance(sel, Yang2019)}
        ffx_grid = [FFX_CUTOFF * 2.0 ** (k / 2) for k in range(-16, 9, 2)]
        self.ffx_sweepers = {name: [FidelityFX(sel.tile_size, cutoff=c, motion_factor=sel.motion_factor,
                                               additional_rates=sel.additional_rates) for c in ffx_grid]
                             for name, sel in selectors.items() if isinstance(sel, FidelityFX)}
        # (method, parameter) -> [failing tiles, pixels saved, tiles, pixels]
        self.acc: dict[tuple[str, str], list[float]] = {}

    def add(self, sample: Any, pred: np.ndarray, gt: np.ndarray, pixels: np.ndarray) -> None:
        """Tally one sample at every grid point of every method (``pixels``: each tile's, :func:`tile_pixels`)."""
        hib = self.hib
        for t in self.model_grid:
            self._tally("model", f"threshold {t:.4g}", select_rates(pred, t, higher_is_better=hib, factors=self.factors),
                        gt, pixels)
        for name, grid in self.yang_grids.items():
            sel = self.selectors[name]
            est_y = sel.predict(sample)
            # the rates its shading_rates allows (NAS's allow_4x4=False: no 4x4), so that the sweep's point at its
            # own threshold is the decision table's row (it chose 4x4 there where the decision took 2x4 or 4x2)
            allowed = None if sel.allow_4x4 else [r for r in PREDICTED_RATES if r != "4x4"]
            for t in grid:
                self._tally(name, f"t {t:.4g}", select_rates(est_y, t, allowed=allowed), gt, pixels)
        for name, sels in self.ffx_sweepers.items():
            for sel in sels:
                self._tally(name, f"cutoff {sel.cutoff:.4g}", sel.shading_rates(sample), gt, pixels)

    def _tally(self, method: str, param: str, codes: np.ndarray, gt: np.ndarray, pixels: np.ndarray) -> None:
        acc = self.acc.setdefault((method, param), [0.0, 0.0, 0.0, 0.0])
        acc[0] += float(failing_tiles(codes, gt, self.thr, self.hib).sum())
        acc[1] += float((_SAVED[codes.astype(np.int64)] * pixels).sum())
        acc[2] += codes.size
        acc[3] += float(pixels.sum())

    def rows(self) -> list[dict[str, Any]]:
        """The report's sweep rows: fail share (of the tiles) and work saved (of the pixels) per (method, parameter)."""
        return [{"method": m, "parameter": prm, "fail_share": a[0] / a[2], "work_saved": a[1] / a[3]}
                for (m, prm), a in self.acc.items()]


class _Run:
    """One evaluation: the model and baselines, and per (method, scene) the tile values that the
    quality and decision tables are computed from."""

    def __init__(self, predictor: Any, store: TargetStore, thr: float, unseen_fraction: float,
                 selectors: dict[str, Any], yang_scored: str | None, sweep: bool) -> None:
        self.predictor, self.store, self.thr, self.unseen_fraction = predictor, store, thr, unseen_fraction
        # the metadata on the predictor's tiles (coarser than the model's with load(tile_size=...))
        self.meta: sdk.ModelMetadata = dataclasses.replace(predictor.metadata, tile_size=predictor.tile_size)
        self.pool = predictor.tile_size // predictor.metadata.tile_size
        self.split = predictor.metadata.tile_size // predictor.tile_size  # (finer hardware tiles, load(tile_size=))
        meta = self.meta
        self.tile, self.metric, self.hib = meta.tile_size, meta.metric, meta.higher_is_better
        self.no_safety = dataclasses.replace(meta, safety=0.0)
        self.rows = [PREDICTED_RATES.index(r) for r in meta.outputs]  # the rates the network predicts
        self.fwd = meta.transform.forward
        self.worse_t = meta.worse_direction
        self.worse_m = -1.0 if self.hib else 1.0
        self.selectors, self.yang_scored = selectors, yang_scored
        self.sweep = _Sweep(thr, self.hib, selectors, meta.rate_factors) if sweep else None
        self.quality: dict[tuple[str, str], _Quality] = {}
        self.decisions: dict[tuple[str, str], _Decisions] = {}
        self.scene_counts: dict[str, int] = {}

    # -- per sample ------------------------------------------------------------------------------
    def add(self, sample: Any) -> dict[str, Any]:
        """Take in one sample; returns its sample, prediction, targets and every method's rates."""
        scene = str(sample.meta.get("scene", "?"))
        self.scene_counts[scene] = self.scene_counts.get(scene, 0) + 1
        pred, pred0, gt = self._predict(sample)
        seen = sample.channel("seen")
        unseen = tile_unseen_share(seen, self.tile) > self.unseen_fraction
        pixels = tile_pixels(seen.shape, self.tile)
        self._add_quality(sample, scene, pred, pred0, gt, unseen)
        codes = self._add_decisions(sample, scene, pred, gt, unseen, pixels)
        if self.sweep is not None:
            self.sweep.add(sample, pred, gt, pixels)
        return {"sample": sample, "pred": pred, "gt": gt, "codes": codes}

    def _predict(self, sample: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The model's values with and without its safety margin, and the sample's targets."""
        x = sample.inputs(self.meta.inputs)
        # predict() is decode(predict_raw()); decoding the one raw output twice gives the engine's
        # values (with the margin) and the margin-free ones without running the network twice.
        raw = self.predictor.predict_raw(x)
        pred = self.meta.decode(raw)
        pred0 = self.no_safety.decode(raw)
        if self.pool > 1:  # the hardware tile takes the worst model tile it covers, as predict() does
            pred = sdk.pool_tiles(pred, self.pool, higher_is_better=self.hib)
            pred0 = sdk.pool_tiles(pred0, self.pool, higher_is_better=self.hib)
        elif self.split > 1:  # each finer hardware tile its model tile's values, as predict() does
            grid = sdk.tile_grid(int(x.shape[-2]), int(x.shape[-1]), self.tile)
            pred, pred0 = (sdk.split_tiles(v, self.split, grid) for v in (pred, pred0))
        gt = self.store.load(sample.id, self.metric, self.tile)
        if gt.shape != pred.shape:
            raise TargetError(f"sample {sample.id}: targets have shape {gt.shape}, the model predicts {pred.shape}")
        return pred, pred0, gt

    def _add_quality(self, sample: Any, scene: str, pred: np.ndarray, pred0: np.ndarray, gt: np.ndarray,
                     unseen: np.ndarray) -> None:
        """Record the scored rates' values of the model (with and without margin) and of Yang 2019."""
        rows, fwd = self.rows, self.fwd
        g_t = fwd(gt[rows])
        for name, p in (("model", pred), ("model (no safety)", pred0)):
            self.quality.setdefault((name, scene), _Quality()).add(fwd(p[rows]), g_t, p[rows], gt[rows], unseen)
        if self.yang_scored is not None:
            est = self.selectors[self.yang_scored].predict(sample)
            self.quality.setdefault((self.yang_scored, scene), _Quality()).add(fwd(est[rows]), g_t, est[rows], gt[rows],
                                                                               unseen)

    def _add_decisions(self, sample: Any, scene: str, pred: np.ndarray, gt: np.ndarray,
                       unseen: np.ndarray, pixels: np.ndarray) -> dict[str, np.ndarray]:
        """Every method's rates (model, oracle, baselines) and whether each tile's rate fails."""
        thr, hib = self.thr, self.hib
        codes = {"model": select_rates(pred, thr, higher_is_better=hib, factors=self.meta.rate_factors),
                 "oracle": select_rates(gt, thr, higher_is_better=hib)}
        for name, sel in self.selectors.items():
            codes[name] = sel.shading_rates(sample)
        for name, c in codes.items():
            self.decisions.setdefault((name, scene), _Decisions()).add(c, failing_tiles(c, gt, thr, hib), unseen, pixels)
        return codes

    # -- the report ------------------------------------------------------------------------------
    def report(self, data: str | os.PathLike[str]) -> EvaluationReport:
        """The report: per scene (and all scenes together) the quality and decision rows, the
        sweeps and the matched work, the notes."""
        meta, scene_counts = self.meta, self.scene_counts
        report = EvaluationReport(
            model=self._model_summary(),
            # resolved, so that the report names the data from any working folder (`rtp evaluate --out` compares
            # it with the next run's: a relative one was read against that run's folder)
            data=str(Path(data).resolve()),
            samples=sum(scene_counts.values()),
            scenes=dict(sorted(scene_counts.items())),
            unseen_fraction=self.unseen_fraction,
            rates=[PREDICTED_RATES[i] for i in self.rows],
            threshold=self.thr,
            baselines={name: sel.params() for name, sel in self.selectors.items()},
            scene_roles=_scene_roles(meta, scene_counts),
        )
        scene_names = sorted(scene_counts) + ([ALL_SCENES] if len(scene_counts) > 1 else [])
        for scene in scene_names:
            report.quality += self._quality_rows(scene)
            report.decisions += self._decision_rows(scene)
        if self.sweep is not None:
            report.sweep = self.sweep.rows()
            target = next(r["fail_share"] for r in report.decisions
                          if r["method"] == "model" and r["split"] == "all" and r["scene"] == scene_names[-1])
            report.matched = _matched(report.sweep, target, {
                r["method"]: r["threshold"] for r in report.decisions if r["scene"] == scene_names[-1]})
        report.notes = _notes(self.metric, self.hib, self.thr, self.selectors, self.unseen_fraction, meta.outputs)
        report.notes += _undefined_notes(report.quality)
        mismatch = _targets_mismatch(meta, self.store)
        if mismatch:
            report.notes.insert(0, mismatch)
        if report.scene_roles and all(r == "train" for r in report.scene_roles.values()):
            report.notes.insert(0, "every evaluated scene was a training scene of this model: these scores are not a test")
            log.warning("every evaluated scene was a training scene of %s", self.predictor.path)
        return report

    def _model_summary(self) -> dict[str, Any]:
        """What the report says about the model."""
        meta = self.meta
        return {
            "path": None if self.predictor.path is None else str(Path(self.predictor.path).resolve()),
            "metric": self.metric, "higher_is_better": self.hib, "tile_size": self.tile,
            "transform": meta.transform.to_dict(), "safety": meta.safety, "inputs": list(meta.inputs),
            "outputs": list(meta.outputs), "default_threshold": meta.default_threshold,
            "model_tile_size": self.predictor.metadata.tile_size,
        }

    def _merged(self, acc: dict[tuple[str, str], Any], method: str, scene: str) -> tuple[np.ndarray, ...]:
        """A method's accumulated arrays over one scene, or over every scene for ``ALL_SCENES``."""
        parts = [acc[(method, s)].merged() for s in sorted(self.scene_counts) if scene in (s, ALL_SCENES)]
        return tuple(np.concatenate(a) for a in zip(*parts))

    def _quality_rows(self, scene: str) -> list[dict[str, Any]]:
        """Quality rows of one scene: per scored method and split, the scores in transformed space
        and the MAE in metric units."""
        out = []
        for method in ["model", "model (no safety)"] + ([self.yang_scored] if self.yang_scored is not None else []):
            p, g, pm, gm, un = self._merged(self.quality, method, scene)
            for split, mask in _split_masks(un.astype(bool)).items():
                s = scores(p[mask], g[mask], worse=self.worse_t)
                sm = scores(pm[mask], gm[mask], worse=self.worse_m)
                out.append({
                    "method": method, "scene": scene,
                    "split": split, "space": "transformed", **s.as_dict(),
                    "mae_metric": sm.mae, "mae_under_metric": sm.mae_under, "spearman": spearman(p[mask], g[mask]),
                })
        return out

    def _decision_rows(self, scene: str) -> list[dict[str, Any]]:
        """Decision rows of one scene: per method and split, the fail share, work saved and rate shares."""
        out = []
        for method in ["model", "oracle", *self.selectors]:
            c, f, un, px = self._merged(self.decisions, method, scene)
            for split, mask in _split_masks(un.astype(bool)).items():
                cm = c[mask].astype(np.int64)
                n_t = int(cm.size)
                # (a share of the pixels, as sdk.work_saved(codes, size, tile) and `rtp play`: the mean over tiles
                # counted a frame's partial edge tiles, the bottom row at 1920x1080 on 16-pixel tiles, as whole)
                shares = {r: float(np.mean(cm == RATE_CODES[r])) if n_t else float("nan") for r in sdk.ALL_RATES}
                out.append({
                    "method": method, "scene": scene, "split": split,
                    "threshold": _method_threshold(method, self.thr, self.selectors), "n": n_t,
                    "fail_share": float(f[mask].mean()) if n_t else float("nan"),
                    "work_saved": float((_SAVED[cm] * px[mask]).sum() / px[mask].sum()) if n_t else float("nan"),
                    "rate_shares": shares,
                })
        return out

    def plots(self, plots_dir: Path, plot_data: dict[str, Any], name: str | None = None,
              palette: str = "paper") -> list[str]:
        """Write the plot sample's figures and the scatter of every model value, named after ``name`` (default:
        the model file's stem), the rate overlays in ``palette``'s colours; returns their paths."""
        every = [self.quality[("model", sc)].merged() for sc in sorted(self.scene_counts)]
        scatter = (np.concatenate([e[0] for e in every]), np.concatenate([e[1] for e in every]))
        stem = Path(str(self.predictor.path)).stem if name is None else name
        return [str(p) for p in _write_plots(plots_dir, {**plot_data, "scatter": scatter}, self.meta, stem, self.thr,
                                             palette)]


def _parameter_value(label: str) -> float:
    """The number a sweep point's parameter ends in (``threshold 0.25``, ``t 8``, ``cutoff 0.05``), NaN for none."""
    try:
        return float(str(label).rsplit(" ", 1)[-1])
    except ValueError:
        return math.nan


def _tie_key(label: str, default: float) -> tuple[float, float]:
    """How :func:`_matched` orders sweep points that save as much: nearest ``default`` (NaN: none), then the
    numerically smallest; a label without a number last."""
    v = _parameter_value(label)
    near = abs(v - default) if math.isfinite(default) else 0.0
    return (near if math.isfinite(near) else math.inf, v if math.isfinite(v) else math.inf)


def _matched(sweep: list[dict[str, Any]], target: float,
             defaults: dict[str, float] | None = None) -> list[dict[str, Any]]:
    """Per method, the work saved at fail share ``target`` read off its sweep as :func:`rtp.evaluate.saved_at`
    reads it (``rtp play``'s matched table and ``bench/report.py`` too): the most any point failing at most
    ``target`` saves, each interpolated linearly towards the next point that fails more where that one saves
    more (of points that fail equally often, the one that saves the most); NaN where the sweep never fails that
    rarely or never that often. The parameter is that point's (``between A and B`` where interpolated); among
    points that save as much, the one nearest the method's parameter in ``defaults`` (the decision table's), else
    the numerically smallest. (The first point at the target's failing share in text order was taken: among ties
    in failures the one that saved the least, "t 11.31" before "t 8".)"""
    defaults = defaults or {}
    out = []
    for method in dict.fromkeys(r["method"] for r in sweep):
        pts = sorted(((float(r["fail_share"]), float(r["work_saved"]), str(r["parameter"])) for r in sweep
                      if r["method"] == method), key=lambda p: (p[0], p[1]))  # (saved_at's order)
        fails = [p[0] for p in pts]
        if not pts or not fails[0] <= target <= fails[-1]:
            out.append({"method": method, "fail_share": target, "work_saved": float("nan"),
                        "parameter": f"fails {100 * min(fails):.1f}..{100 * max(fails):.1f}% over the sweep"
                        if pts else "no sweep"})
            continue
        default = float(defaults.get(method, math.nan))
        # per failing share the points that save the most (the others, as often failing, are alternatives that save
        # less), and of them the one a reading names (:func:`_tie_key`): the line from a point that fails less runs
        # towards it (it ran towards the next point in order, the one of that share that saved the least)
        top: dict[float, float] = {}
        for f, w, _ in pts:
            top[f] = max(w, top.get(f, w))
        upper = [q for q in pts if q[1] == top[q[0]]]
        named = {f: min((q for q in upper if q[0] == f), key=lambda q: _tie_key(q[2], default)) for f in top}
        levels = sorted(top)
        best: tuple[float, str, tuple[float, float]] | None = None
        for f0, w0, p0 in upper:
            if f0 > target:
                break
            i = levels.index(f0)
            nxt = named[levels[i + 1]] if i + 1 < len(levels) else None
            if nxt is None or f0 == target or nxt[1] < w0:  # (towards one saving less: this one)
                saved, param = w0, p0
            else:
                frac = min(1.0, (target - f0) / (nxt[0] - f0))
                saved = w0 + (nxt[1] - w0) * frac
                param = nxt[2] if frac == 1.0 else f"between {p0} and {nxt[2]}"
            key = _tie_key(p0 if param.startswith("between ") else param, default)
            if best is None or saved > best[0] or (saved == best[0] and key < best[2]):
                best = (saved, param, key)
        assert best is not None  # (fails[0] <= target)
        out.append({"method": method, "fail_share": target, "work_saved": float(best[0]), "parameter": best[1]})
    return out


def _scene_roles(meta: sdk.ModelMetadata, scenes: dict[str, int]) -> dict[str, str]:
    prov = meta.provenance
    train = {str(x) for x in prov.get("train_scenes", ()) or ()}
    val = {str(x) for x in prov.get("val_scenes", ()) or ()}
    return {s: "train" if s in train else "validation" if s in val else "new" for s in sorted(scenes)}


def _method_threshold(method: str, thr: float, selectors: dict[str, Any]) -> float:
    sel = selectors.get(method)
    if sel is None:
        return thr
    return float(getattr(sel, "threshold", getattr(sel, "cutoff", thr)))


def _undefined_notes(quality: list[dict[str, Any]]) -> list[str]:
    """Why rows of tiles (``n`` > 0) read "-" for R² % or Spearman (null in the JSON): the row's targets, or for
    Spearman its predictions (a constant predictor's), are all one value. (They read "-" without a word of why.)"""
    def where(rows: list[dict[str, Any]]) -> str:
        names = [f"{r['scene']}/{r['split']}/{r['method']}" for r in rows]
        return ", ".join(names[:3]) + (f", ... ({len(names)} rows)" if len(names) > 3 else "")

    def undefined(key: str) -> list[dict[str, Any]]:
        return [r for r in quality if r["n"] and (r[key] is None or not math.isfinite(r[key]))]

    out = []
    if r2 := undefined("r2"):
        out.append("R² % reads '-' (null in evaluation.json) where a row's targets are all one value: R² is undefined "
                   f"without variance to explain; here {where(r2)}.")
    if rank := undefined("spearman"):
        out.append("Spearman reads '-' (null in evaluation.json) where a row's predictions or targets are all one value "
                   f"(a constant predictor's, say) or it holds one value: a rank correlation is undefined; here "
                   f"{where(rank)}.")
    return out


def _yang_variants(selectors: dict[str, Any]) -> tuple[str | None, str | None]:
    """The names of the Yang 2019 selectors among ``selectors``, by their kind: the one that reads unseen tiles as
    they are (``unseen="as_is"``, the one the quality table scores) and the one that shades them at 1x1; None for
    either that is not there."""
    def named(unseen: str) -> str | None:
        return next((n for n, s in selectors.items() if isinstance(s, Yang2019) and s.unseen == unseen), None)

    return named("as_is"), named("full")


def _notes(metric: str, hib: bool, thr: float, selectors: dict[str, Any], frac: float, outputs: Sequence[str]) -> list[str]:
    notes = [
        "R² %, MAE, MAE under., σ MAE and under % are in the model's transformed space (as the paper reports them); "
        f"MAE [{metric}] is in metric units. 'model' includes the safety margin (what an engine gets).",
        f"Scored rates: the network's own outputs ({', '.join(outputs)}); extrapolated rates enter the decisions only.",
        f"'fails %': tiles whose chosen rate's true {metric} {'is not above' if hib else 'reaches'} {thr:g}; "
        "1x1 never fails. 'work saved %': 1 - 1/(W·H) of the chosen rate, averaged over the tiles weighted by the "
        "pixels each holds (a partial tile at the frame's edge its real ones).",
    ]
    as_is, full = _yang_variants(selectors)
    if (either := as_is or full) is not None:
        yang = selectors[either]
        if metric != "jnyang":
            notes.append(
                f"Yang 2019 estimates a JNYang-like quantity (Weber-normalised luma difference of the previous frame), "
                f"not {metric}: its scores measure how well that proxy tracks {metric}, and its decisions use its own "
                f"sensitivity t = {yang.threshold:g}."
                + (" Its quality rows are left out: PSNR runs the other way." if hib else "")
            )
        # (the variant's own share: built from a Yang2019 given to evaluate(yang=), it keeps that one's, and the note
        # named the evaluation's --unseen-fraction, which it did not use)
        full_frac = selectors[full].unseen_fraction if full is not None else frac
        notes.append(
            "Yang 2019 reads only the reprojected previous frame: unseen pixels are black there, so unseen tiles get "
            f"a zero estimate and the coarsest rate (RT-Percept's YangVRS does the same); '{full or 'yang2019-unseen-1x1'}' "
            f"instead shades tiles more than {100 * full_frac:g}% unseen at 1x1."
        )
    if any(n.startswith("fidelityfx") for n in selectors):
        notes.append(
            "FidelityFX makes decisions from luma deltas, not metric estimates: it appears only in the decision "
            "table, with its own cutoff; its base path picks among 1x1, 1x2, 2x1, 2x2."
        )
    return notes


def _write_plots(out: Path, d: dict[str, Any], meta: sdk.ModelMetadata, stem: str, threshold: float,
                 palette: str = "paper") -> list[Path]:
    from . import plots as P

    out.mkdir(parents=True, exist_ok=True)
    sample = d["sample"]
    h, w = sample.size
    scale = max(1, *sdk.tile_grid(h, w, 640))  # downscale so the longer side fits in 640 pixels
    fwd = meta.transform.forward

    def bright_is_worse(v: np.ndarray) -> np.ndarray:
        t = fwd(v)
        return 1.0 - t if meta.worse_direction < 0 else t

    # Transformed space (as the paper plots it): 0..1; the heatmaps oriented so that bright is worse for every
    # metric, the scatter in the transform's own direction (PSNR's: 1 is the best).
    label = f"{meta.metric} ({meta.transform.type} transform, 1 = worst)"
    scatter_label = f"{meta.metric} ({meta.transform.type} transform, {'1' if meta.worse_direction > 0 else '0'} = worst)"
    paths = [out / f"{stem}_heatmaps.png", out / f"{stem}_scatter.png", out / f"{stem}_rates.png"]
    p_all, g_all = d["scatter"]
    # every figure drawn before the first is written: a failure while drawing leaves the folder as it was, not
    # this evaluation's heatmaps beside the previous one's scatter
    images = [
        P.heatmaps(bright_is_worse(d["gt"]), bright_is_worse(d["pred"]), meta.tile_size, (h, w),
                   seen=sample.channel("seen"), scale=scale, label=label,
                   threshold=float(bright_is_worse(np.float64(threshold))),
                   title=f"{stem} on sample {sample.id}: true and predicted {meta.metric} per {meta.tile_size}px tile"),
        P.scatter(p_all, g_all, label=scatter_label,
                  title=f"{stem}: predicted vs true {meta.metric}, {p_all.size} tile values"),
        P.rate_overlays(sample.final("1x1"), d["codes"], meta.tile_size, scale=scale, palette=palette,
                        title=f"rates chosen on sample {sample.id}; 'model': {stem} at {meta.metric} threshold "
                              f"{threshold:g}"),
    ]
    for path, image in zip(paths, images, strict=True):
        P.save_image(path, image)
    return paths
