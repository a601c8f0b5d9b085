"""The closed-loop benchmark over several maps: one table from the play.json files of `rtp play`.

Reads each run's matched-quality rows (work saved where a method fails on 1%, 2% and 5% of the
tiles) and prints, per map and path, every method's savings, then issue 12's targets: rtp against
the better of the two Yang 2019 variants at equal failing share, rtp's share of the oracle's saving
and prediction reuse against k = 1. Savings read at a share a method's sweep never failed that often
are lower bounds (">=") and are left out of the ratios, as in `PlayReport.ratios`.

    python bench/play_report.py data/play-{20kdm2,oa_dm5,oacmpctf3,delta,oasago2}/play.json
    python bench/play_report.py data/play-*-seed1/play.json --reuse jnyang@4:worst,jnyang@4:mean
    python bench/play_report.py data/playlong-kaos/play.json --window 150 --by-age
    python bench/play_report.py data/playr-*/play.json --reuse jnyang@4,jnyang@4:r0.05 --plot-reuse reuse.png
    python bench/play_report.py data/play-{kaos,oa_dm3,oacmpdm4}-budget/play.json --worst-frames

``--window N`` adds, per path and method, the saving and the failing share at the method's default
parameter in consecutive windows of N frames (the per-frame series of play.json; the first frame,
which has no history, left out): whether a long path drifts. ``--by-age`` adds, per path and
method with prediction reuse (``NAME@k``, unseen tiles at 1x1 and no ``:rS`` refresh: its network runs
on every k-th frame), the same two figures grouped by frames since the network ran (0: it ran), beside the
method without reuse on the same frames: whether reuse's loss grows with the estimates' age.
``--worst-frames`` adds the worst 5% of frames' saving (each run's 5th percentile of its per-frame saving)
read off each method's sweep at the same failing shares (">=" where the sweep never failed that often: a lower
bound, as in the matched table and play.md's): what a frame-time budget plans for, and where a
budget (``NAME@k:bS``, the same saving on every frame) and a threshold part.
With several paths the report ends with each reuse method's mean over them (kept share at each
level, worst path, network work); ``--plot-reuse PNG`` draws the kept share at 5% against the work (refused,
before any table, where the runs give it nothing to draw: no --model, no reuse method, or no path with both).

Every run must share the settings the header states (frames, frame rate, size, the failure metric and
threshold): runs that differ in one are refused, naming the setting and the files, before any table (their
rows would sit under another run's header, their savings averaged in one mean, their windows under another
run's columns); report them one setting at a time. Runs on other hardware tiles (``--tile-size``) share the
tables, each row labelled with its tiles, and each tile size has its own mean rows.

Runs with different methods share one table: its columns are every method of any run, blank where
a run did not play it. Runs of the same map, seed, frames, size, failure threshold and sweep grids
(as recorded, or read off the thresholds in the rows of runs from before the grids were recorded)
are merged into one row per path (every method has its own history, so a method's numbers do not depend on
which others ran beside it): `jnyang,jnyang@4` in one run and `jnyang@2` in another compare, and a run of
the slow path beside one of the fast path gives both rows (until 2026-12-07 the second run's path was dropped).
A method played on one path and not the other is blank on the other, as a method a run did not play.
Runs merged across the loop's settings (history, shading, engine_rates, dynamic_resolution: the open
loop, the composite, ...), which the key leaves out so that runs recorded before them still merge, are
named in a note with both values.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

from _common import PLAY_JSON, UsageError, count, run_main, save_figure  # bench/ is on sys.path when run as a script

from rtp import sdk
from rtp.evaluate import METHOD_KINDS, fail_rule, saved_at

LEVELS = (0.01, 0.02, 0.05)
#: The methods that are not swept: the oracle, and the oracle on the monotone truth (the ceiling of a
#: predictor that orders the rates; its column in the targets appears when a run played it).
ORACLES = ("oracle", "oracle-monotone")


#: The settings of the closed loop a run records besides its key (map, seed, frames, size, failing rule, tiles): runs
#: that differ in one are merged, with a note.
_LOOP_SETTINGS = ("history", "shading", "engine_rates", "dynamic_resolution")


def _cell(m: dict[str, Any] | None) -> str:
    if m is None or not math.isfinite(m["work_saved"]):
        return "-"
    return f"{'>= ' if m.get('capped') else ''}{100 * m['work_saved']:.1f}"


def _readable(m: dict[str, Any] | None) -> bool:
    return m is not None and not m.get("capped") and math.isfinite(m["work_saved"]) and m["work_saved"] > 0


def _ratio(a: dict[str, Any] | None, b: dict[str, Any] | None) -> float:
    return a["work_saved"] / b["work_saved"] if _readable(a) and _readable(b) else math.nan  # type: ignore[index]


def _grids(rep: dict[str, Any]) -> dict[str, list[float]] | None:
    """The sweep grids a run was read off: as recorded, or, for runs before 2026-11-26 that did not
    record them, inferred from its rows (each model's and each baseline's swept values over its
    default's; None if the rows do not tell). Keys: ``model`` (multiples of a model's threshold; a
    PSNR model's dB offsets give other ratios and so never match) and ``baseline``."""
    recorded = rep["settings"].get("grids")
    if recorded:
        return {k: [round(v, 6) for v in recorded[k]] for k in ("model", "baseline")}
    baselines = set(METHOD_KINDS) - set(ORACLES) - {"full"}
    out: dict[str, list[float]] = {}
    for method in {r["method"] for r in rep.get("rows", [])} - set(ORACLES) - {"full"}:
        rows = [r for r in rep["rows"] if r["method"] == method and r.get("value") is not None]
        default = next((r["value"] for r in rows if r.get("default")), None)
        if not default:
            continue
        grid = sorted({round(r["value"] / default, 6) for r in rows})
        kind = "baseline" if method in baselines else "model"
        if out.setdefault(kind, grid) != grid:  # two models swept differently: no one grid
            out[kind] = []
    return out or None


def _same_grids(a: dict[str, list[float]] | None, b: dict[str, list[float]] | None) -> bool:
    """Whether two runs were swept alike wherever both show a grid (two runs that do not tell: alike)."""
    if a is None or b is None:
        return a is None and b is None
    return all(a[k] == b[k] and a[k] for k in a.keys() & b.keys())


def _mean_cell(per_path: list[list[dict[str, Any] | None] | None]) -> str:
    """The mean over the paths of a method's matched savings, level by level: ``-`` where a path has none
    (the method did not play it, or its sweep never failed that rarely), ``>=`` where a path's is a lower
    bound (its sweep never failed that often), as the rows' cells."""
    if any(p is None for p in per_path):
        return "-"
    out = []
    for level in zip(*per_path):  # type: ignore[misc]
        if any(m is None or not math.isfinite(m["work_saved"]) for m in level):
            out.append("-")
            continue
        mean = sum(m["work_saved"] for m in level) / len(level)
        out.append(f"{'>= ' if any(m.get('capped') for m in level) else ''}{100 * mean:.1f}")
    return " / ".join(out)


def _fmt(r: float, pct: bool = False) -> str:
    """A share of the oracle's saving to a tenth of a percent, a ratio to two decimals, three within 1% of a tie:
    the targets are 90% and 1.0x / 1.3x, and a rounded "90%" or "1.00x" hid 89.85% and 0.994x."""
    if not math.isfinite(r):
        return "-"
    if pct:
        return f"{100 * r:.1f}%"
    return f"{r:.3f}x" if abs(r - 1.0) < 0.01 else f"{r:.2f}x"


#: The settings the tables' header states, which every run must share: (name, how a run's is read).
SHARED: tuple[tuple[str, Any], ...] = (
    ("frames", lambda s: str(s["frames"])),
    ("frame rate", lambda s: f"{s['fps']:g} Hz"),
    ("size", lambda s: "x".join(str(v) for v in s["size"])),
    ("fail metric", lambda s: str(s["fail_metric"])),
    ("fail threshold", lambda s: f"{s['fail_threshold']:g}"),
)


def _check_shared(reports: list[tuple[Path, dict[str, Any]]]) -> None:
    """Refuse runs whose header settings (:data:`SHARED`) differ, naming the first such setting and the files."""
    for name, read in SHARED:
        files: dict[str, list[str]] = {}
        for path, rep in reports:
            files.setdefault(read(rep["settings"]), []).append(str(path))
        if len(files) > 1:
            said = " against ".join(f"{value} ({', '.join(ps[:3])}{f' and {len(ps) - 3} more' if len(ps) > 3 else ''})"
                                    for value, ps in files.items())
            raise UsageError(f"the runs differ in {name}: {said}; one table reads runs of one setting: report them "
                             "apart")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=PLAY_JSON, help="play.json files of `rtp play --out DIR` (or the DIRs)")
    ap.add_argument("--model", default="jnyang", help="the rtp method to compare (default jnyang)")
    ap.add_argument("--reuse", default=None, help="comma-separated methods with prediction reuse to compare with "
                    "--model (default MODEL@4)")
    ap.add_argument("--window", type=count, default=0, help="also print each method's saving and failing share at its "
                    "default in consecutive windows of this many frames")
    ap.add_argument("--by-age", action="store_true", help="also print each reuse method's saving and failing share at "
                    "its default by frames since its network ran, beside the method without reuse")
    ap.add_argument("--worst-frames", action="store_true", help="also print the worst 5%% of frames' saving at the "
                    "same failing shares, read off each method's sweep (runs since 2026-12-05)")
    ap.add_argument("--plot-reuse", type=Path, default=None, metavar="PNG", help="also plot each reuse method's kept "
                    "share of MODEL's saving at 5%% failing tiles against its network work per frame, per path")
    args = ap.parse_args()
    model = args.model
    reuses = [r.strip() for r in (args.reuse or f"{model}@4").split(",") if r.strip()]
    reports = [(run, json.loads(run.read_text(encoding="utf-8"))) for run in args.runs]
    _check_shared(reports)  # (before any table: one header, one mean, one set of windows)
    notes: list[str] = []  # (printed once the runs are known to make the tables asked for)
    runs: list[dict[str, Any]] = []
    for run, rep in reports:
        s = rep["settings"]
        # runs before 2026-11-26 do not record their sweep grids (six points per method then): read off the rows
        grids = _grids(rep)
        # (a run on other hardware tiles is another run: runs before 2026-12-04 played 16-pixel tiles only)
        key = (s["scene"], s["seed"], s["frames"], tuple(s["size"]), s["fail_metric"], s["fail_threshold"],
               s.get("tile_size", sdk.DEFAULT_TILE_SIZE))
        same = next((r for r in runs if r["_key"] == key and _same_grids(r["_grids"], grids)), None)
        if same is None and any(r["_key"] == key for r in runs):
            notes.append(f"note: {run} was swept over other grids than a run of the same map and path before it: "
                         "its rows are not merged\n")
        if same is None:
            runs.append({**rep, "_key": key, "_grids": grids,
                         "settings": {**s, "methods": list(s["methods"]), "cameras": dict(s.get("cameras") or {}),
                                      "reuse": dict(s.get("reuse") or {})},
                         "matched": list(rep["matched"]), "rows": list(rep.get("rows", [])),
                         "unseen": dict(rep["unseen"]), "frames": dict(rep.get("frames") or {}),
                         # which methods each path holds (a merged run may add a path, or methods on one path only)
                         "_played": {path: set(s["methods"]) for path in rep["unseen"]}})
            continue
        same["_grids"] = {**(grids or {}), **(same["_grids"] or {})} or None
        # the loop's settings, which the key leaves out (runs before some of them were recorded still merge): a run
        # of the open loop, of the composite, with engine rates or dynamic resolution is another experiment
        differ = [k for k in _LOOP_SETTINGS if k in s and k in same["settings"] and s[k] != same["settings"][k]]
        if differ:
            both = "; ".join(f"{k}: {same['settings'][k]!r} and {s[k]!r}" for k in differ)
            notes.append(f"note: {run} was played with another {', '.join(differ)} than a run of the same map before "
                         f"it ({both}): its rows are merged with that run's, as the key names neither\n")
        # per path, the methods this run adds there: a path the first run did not play is added whole (it was
        # dropped, and with it every method of a run of the other path), a path both played gains the new methods
        for path, unseen in rep["unseen"].items():
            played = same["_played"].setdefault(path, set())
            new = [m for m in s["methods"] if m not in played]
            if not new:
                continue
            played.update(new)
            if path not in same["unseen"]:
                same["unseen"][path] = unseen
                if path in (s.get("cameras") or {}):
                    same["settings"]["cameras"][path] = s["cameras"][path]
            same["matched"] += [m for m in rep["matched"] if m["path"] == path and m["method"] in new]
            same["rows"] += [r for r in rep.get("rows", []) if r["path"] == path and r["method"] in new]
            series = (rep.get("frames") or {}).get(path, {})  # (--window and --by-age read them)
            same["frames"][path] = {**same["frames"].get(path, {}), **{m: series[m] for m in new if m in series}}
            same["settings"]["methods"] += [m for m in new if m not in same["settings"]["methods"]]
            same["settings"]["reuse"].update({m: v for m, v in (s.get("reuse") or {}).items() if m in new})
    tiles = sorted({r["_key"][-1] for r in runs})

    for rep in runs:  # the map, and its tiles where the runs played several sizes
        rep["_label"] = rep["settings"]["scene"] + (f" ({rep['_key'][-1]}px)" if len(tiles) > 1 else "")

    def label(s: dict[str, Any]) -> str:
        return str(next(r["_label"] for r in runs if r["settings"] is s))

    def grouped(name: str, tile: int) -> str:
        """A name in a table of several tile sizes: its tile size said (their figures are not averaged together)."""
        return name if len(tiles) == 1 else f"{name} ({tile}px)"

    head: list[str] = []
    for rep in runs:
        head += [m for m in rep["settings"]["methods"] if m not in head]
    # reuse columns only for methods the runs played (by default MODEL@4 where it was)
    unplayed = [r for r in reuses if r not in head]
    if unplayed and args.reuse:
        notes.append(f"note: the runs did not play {', '.join(unplayed)} (--reuse): no column for it\n")
    reuses = [r for r in reuses if r in head]
    if args.plot_reuse and model not in head:
        raise UsageError(f"--plot-reuse: the runs did not play {model} (--model), whose saving the reuse methods keep a "
                         "share of: nothing to plot")
    if args.plot_reuse and not reuses:
        raise UsageError(f"--plot-reuse: the runs played no reuse method of {', '.join(unplayed)} (--reuse names them): "
                         "nothing to plot")
    rows, targets = [], []
    path_tiles: list[int] = []  # each row's tile size (its mean row's)
    # each method's matched entries over the paths, for the mean row (None: the method did not play the path)
    matched: dict[str, list[list[dict[str, Any] | None]]] = {meth: [] for meth in head}
    # per reuse method (and tile size) and path: ratios, work
    kept: dict[str, list[tuple[str, list[float], float]]] = {grouped(r, t): [] for r in reuses for t in tiles}
    for rep in runs:
        s = rep["settings"]
        for path, unseen in rep["unseen"].items():
            methods = rep["_played"][path]  # (the methods this path holds, of the runs merged into this one)
            u = unseen[1:]
            cam = s.get("cameras", {}).get(path, {})
            eye = f"{cam['eye_height_m']:.2f}" if cam else "?"
            at = {(m["method"], m["fail_share"]): {**m, "work_saved": math.nan if m["work_saved"] is None else m["work_saved"]}
                  for m in rep["matched"] if m["path"] == path}  # play.json writes nan as null
            path_tiles.append(rep["_key"][-1])
            for meth in head:
                matched[meth].append(None if meth not in methods else
                                     [at.get((meth, lv)) for lv in (LEVELS if meth not in ORACLES else LEVELS[:1])])
            cells = ["" if meth not in methods else " / ".join(_cell(at.get((meth, lv))) for lv in LEVELS)
                     if meth not in ORACLES else _cell(at.get((meth, LEVELS[0]))) for meth in head]
            rows.append(f"| {label(s)} | {s['seed']} | {path} | {eye} | {100 * sum(u) / len(u):.2f} / {100 * max(u):.2f} | "
                        + " | ".join(cells) + " |")
            yang = [max((m for y in ("yang2019", "yang2019-unseen-1x1") if _readable(m := at.get((y, lv)))),
                        key=lambda m: m["work_saved"], default=None) for lv in LEVELS]
            vs_yang = [_ratio(at.get((model, lv)), y) for lv, y in zip(LEVELS, yang)]
            of_oracles = [[_ratio(at.get((model, lv)), at.get((o, LEVELS[0]))) for lv in LEVELS]
                          for o in ORACLES if o in head]
            reused = [[_ratio(at.get((r, lv)), at.get((model, lv))) for lv in LEVELS] for r in reuses]
            # the network's work per frame (a share of a whole-frame run) at each reuse method's default
            work = [next((r["network_frames"] for r in rep.get("rows", []) if r["path"] == path and r["method"] == m
                          and r["default"] and r.get("network_frames") is not None), math.nan) for m in reuses]
            for r, rs, w in zip(reuses, reused, work):
                if r in methods:
                    kept[grouped(r, rep["_key"][-1])].append((f"{label(s)} {path}", rs, w))
            cells = [" / ".join(_fmt(r, pct) for r in rs) for rs, pct in [(vs_yang, False)] + [(o, True) for o in of_oracles]]
            if not any(y in head for y in ("yang2019", "yang2019-unseen-1x1")):
                cells = cells[1:]  # (no Yang 2019 played: no column of dashes)
            cells += [" / ".join(_fmt(r, True) for r in rs) + ("" if not math.isfinite(w) else f" (network {100 * w:.0f}%)")
                      for rs, w in zip(reused, work)]
            targets.append(f"| {label(s)} | {s['seed']} | {path} | " + " | ".join(cells) + " |")
    if args.plot_reuse and not any(math.isfinite(w) and math.isfinite(rs[-1]) for per in kept.values() for _, rs, w in per):
        raise UsageError(f"--plot-reuse: no path of {', '.join(reuses)} has both a readable share of {model}'s saving at "
                         f"{100 * LEVELS[-1]:g}% failing tiles and the network's work per frame (runs before it was "
                         "recorded, or sweeps capped there): nothing to plot")
    s = runs[0]["settings"]  # (every run shares these: _check_shared)
    for note in notes:
        print(note)
    print(f"{s['frames']} frames at {s['fps']:g} Hz, {s['size'][0]}x{s['size'][1]}, "
          + (f"{tiles[0]}-pixel tiles" if len(tiles) == 1 else "tiles as each map says, each size its own mean")
          + " (seed: which path); a tile fails "
          f"when {fail_rule(s['fail_metric'], s['fail_threshold'])}. Work saved % at "
          + " / ".join(f"{100 * v:g}" for v in LEVELS) + "% failing tiles (>=: a lower bound, the "
          "method's sweep never failed that often; -: never that rarely).\n")
    print("| map | seed | path | eye (m) | unseen % mean / max | " + " | ".join(head) + " |")
    print("|---|---:|---|---:|---|" + "---|" * len(head))
    print("\n".join(rows))
    for tile in tiles:  # the mean over each tile size's paths (a method that did not play every path has none)
        mine = [i for i, t in enumerate(path_tiles) if t == tile]
        if len(mine) > 1:
            print(f"| {grouped('mean', tile)} | | | | | "
                  + " | ".join(_mean_cell([matched[meth][i] for i in mine]) for meth in head) + " |")
    yang_played = any(y in head for y in ("yang2019", "yang2019-unseen-1x1"))
    if model in head:
        print(f"\nTargets (at 1 / 2 / 5% failing tiles; -: not readable, a sweep capped or never that rare): {model} over the "
              "better Yang 2019 (>= 1.3x fast, >= 1.0x slow)" + ("" if yang_played else ", not played") + ", its share of "
              "the oracle's saving (>= 90%), reuse at k = 4 against k = 1 (>= 95%; in brackets the network's work per "
              "frame, a share of a whole-frame run)\n")
        oracles = [o for o in ORACLES if o in head]
        columns = ([f"{model} / Yang"] if yang_played else []) + [f"{model} / {o}" for o in oracles] \
            + [f"{r} / {model}" for r in reuses]
        print("| map | seed | path | " + " | ".join(columns) + " |")
        print("|---|---:|---|" + "---|" * len(columns))
        print("\n".join(targets))
        _reuse_summary(kept, model)
        if args.plot_reuse:
            _plot_reuse(kept, model, args.plot_reuse)
    else:
        print(f"\n(No targets: the runs did not play {model}; --model names the rtp method to compare.)")
    if args.worst_frames:
        _worst_frames(runs, head, label, grouped)
    if args.window:
        _windows(runs, args.window)
    if args.by_age:
        _by_age(runs)


def _worst_frames(runs: list[dict[str, Any]], head: list[str], label: Any, grouped: Any) -> None:
    """Per map, path and method, the worst 5% of frames' saving (the rows' ``work_saved_p05``) read off the
    method's sweep at each failing share as the matched saving is (``evaluate.saved_at``), and the mean
    (one per tile size: ``grouped('mean', tile)`` names it)."""
    print("\nThe worst 5% of frames' saving % at " + " / ".join(f"{100 * v:g}" for v in LEVELS) + "% failing tiles "
          "(each run's 5th percentile of its per-frame saving, read off the sweep; >=: a lower bound, the method's "
          "sweep never failed that often; -: not readable, or a run from before the figure):\n")
    print("| map | seed | path | " + " | ".join(head) + " |")
    print("|---|---:|---|" + "---|" * len(head))
    per: dict[str, list[list[float] | None]] = {meth: [] for meth in head}
    # per method and path, at each level, whether the reading is a lower bound (the matched table's ">=": the sweep
    # never failed that often; until 2026-12-07 it read here as a plain saving, and its mean as a plain mean)
    low: dict[str, list[list[bool]]] = {meth: [] for meth in head}
    path_tiles: list[int] = []
    for rep in runs:
        s = rep["settings"]
        for path in rep["unseen"]:
            path_tiles.append(rep["_key"][-1])
            cells = []
            for meth in head:
                pts = [(r["fail_share"], r.get("work_saved_p05")) for r in rep.get("rows", [])
                       if r["path"] == path and r["method"] == meth]
                levels = LEVELS if meth not in ORACLES else LEVELS[:1]
                # (as rtp play marks them: a swept method, not full nor an oracle, whose every point fails less)
                most = max((f for f, _ in pts if f is not None and math.isfinite(f)), default=math.inf)
                low[meth].append([meth not in (*ORACLES, "full") and most < lv for lv in levels])
                if not pts or any(v is None or not math.isfinite(v) for _, v in pts):
                    per[meth].append(None)
                    cells.append("" if meth not in rep["_played"][path] else "-")
                    continue
                got = [saved_at(pts, lv) for lv in levels]
                values = [math.nan if v is None else v for v in got]
                per[meth].append(values)
                cells.append(" / ".join("-" if not math.isfinite(v) else f"{'>= ' if c else ''}{100 * v:.1f}"
                                        for v, c in zip(values, low[meth][-1])))
            print(f"| {label(s)} | {s['seed']} | {path} | " + " | ".join(cells) + " |")
    for tile in sorted(set(path_tiles)):
        mine = [i for i, t in enumerate(path_tiles) if t == tile]
        if len(mine) < 2:
            continue
        means = []
        for meth in head:
            values = [per[meth][i] for i in mine]
            if any(v is None for v in values):
                means.append("-")
                continue
            cols = list(zip(*[v for v in values if v is not None]))
            bounds = [any(c) for c in zip(*[low[meth][i] for i in mine])]
            means.append(" / ".join("-" if not all(math.isfinite(x) for x in c) else
                                    f"{'>= ' if b else ''}{100 * sum(c) / len(c):.1f}" for c, b in zip(cols, bounds)))
        print(f"| {grouped('mean', tile)} | | | " + " | ".join(means) + " |")


def _reuse_summary(kept: dict[str, list[tuple[str, list[float], float]]], model: str) -> None:
    """Per reuse method (and tile size, where the runs played several) over every path it ran: the mean kept share
    (unrounded ratios) at each level, the worst path at 5%, how many paths keep >= 95% there, and the mean network
    work per frame."""
    if max((len(per) for per in kept.values()), default=0) < 2:
        return
    print(f"\nOver the paths (mean of the unrounded ratios to {model}; paths whose ratio is not readable left out):\n")
    print("| method | paths | network work per frame | kept at " + " / ".join(f"{100 * v:g}" for v in LEVELS)
          + "% | worst path at 5% | paths >= 95% at 5% |")
    print("|---|---:|---:|---|---:|---:|")
    for r, per in kept.items():
        if not per:
            continue
        means = []
        for j in range(len(LEVELS)):
            vals = [rs[j] for _, rs, _ in per if math.isfinite(rs[j])]
            means.append(sum(vals) / len(vals) if vals else math.nan)
        at5 = [(rs[-1], name) for name, rs, _ in per if math.isfinite(rs[-1])]
        works = [w for _, _, w in per if math.isfinite(w)]
        worst = min(at5) if at5 else (math.nan, "-")
        shares = ("-" if not any(math.isfinite(m) for m in means)  # (one dash, not "- / - / -%")
                  else " / ".join("-" if not math.isfinite(m) else f"{100 * m:.1f}" for m in means) + "%")
        print(f"| {r} | {len(per)} | {'-' if not works else f'{100 * sum(works) / len(works):.1f}%'} | {shares} | "
              + ("-" if not at5 else f"{100 * worst[0]:.1f}% ({worst[1]})") + f" | {sum(v >= 0.95 for v, _ in at5)} |")


def _plot_reuse(kept: dict[str, list[tuple[str, list[float], float]]], model: str, out: Path) -> None:
    """Kept share of ``model``'s saving at 5% failing tiles against the network's work per frame: one
    colour per reuse method, a small marker per path (hollow: slow, filled: fast), a large one for the mean."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    for i, (r, per) in enumerate(kept.items()):
        pts = [(100 * w, 100 * rs[-1], name) for name, rs, w in per if math.isfinite(w) and math.isfinite(rs[-1])]
        if not pts:
            continue
        colour = f"C{i % 10}"
        for x, y, name in pts:
            ax.scatter(x, y, s=28, edgecolors=colour, facecolors="none" if name.endswith("slow") else colour)
        mx, my = sum(p[0] for p in pts) / len(pts), sum(p[1] for p in pts) / len(pts)
        ax.scatter(mx, my, s=150, marker="D", color=colour, edgecolors="black", label=f"{r} (mean)", zorder=3)
    ax.axhline(95, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("network work per frame (% of a whole-frame run)")
    ax.set_ylabel(f"kept of {model}'s saving at 5% failing tiles (%)")
    ax.set_title("Prediction reuse: quality kept against network work\n(small: one path, hollow slow, filled fast; "
                 "large: the mean)", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3)
    save_figure(fig, out)


def _windows(runs: list[dict[str, Any]], n: int) -> None:
    """Per map, path and method: work saved / failing tiles % at the default in windows of ``n`` frames."""
    print(f"\nAt each method's default, work saved / failing tiles % per window of {n} frames (frames counted from "
          "the first with a history)\n")
    out = []
    longest = 0
    for rep in runs:
        s = rep["settings"]
        for path, methods in rep.get("frames", {}).items():
            for meth, series in methods.items():
                saved, fail = series["saved"][1:], series["fail"][1:]
                longest = max(longest, len(saved))
                cells = []
                for i in range(0, len(saved), n):
                    w, f = saved[i:i + n], fail[i:i + n]
                    cells.append(f"{100 * sum(w) / len(w):.1f} / {100 * sum(f) / len(f):.1f}")
                out.append(f"| {rep['_label']} | {s['seed']} | {path} | {meth} | " + " | ".join(cells) + " |")
    starts = range(0, longest, n)
    print("| map | seed | path | method | " + " | ".join(f"frames {1 + i}-{min(i + n, longest)}" for i in starts) + " |")
    print("|---|---:|---|---|" + "---|" * len(starts))
    print("\n".join(out))


def _by_age(runs: list[dict[str, Any]]) -> None:
    """Per map, path and reuse method (unseen tiles at 1x1 and no refresh share, so the network runs on frames 0, k,
    2k, ...):
    work saved / failing tiles % at the default by frames since the network ran, and the same frames
    of the method without reuse (the model it names)."""
    out = []
    longest = 0
    for rep in runs:
        s = rep["settings"]
        for path, methods in rep.get("frames", {}).items():
            for meth, spec in s.get("reuse", {}).items():
                base = meth.rsplit("@", 1)[0]  # (a model file's own "@" stays: model@v2.onnx@4 reuses model@v2.onnx)
                # (a refresh share, :rS, runs the network early and restarts the interval: its frames' ages are not
                # their index modulo k, and were reported as if they were)
                if meth not in methods or spec.get("unseen", "full") != "full" or spec.get("refresh") is not None:
                    continue
                k = int(spec["k"])
                longest = max(longest, k)
                for name in (meth, base) if base in methods else (meth,):
                    saved, fail = methods[name]["saved"], methods[name]["fail"]
                    cells = []
                    for age in range(k):
                        idx = [i for i in range(1, len(saved)) if i % k == age]  # frame 0 has no history
                        cells.append(f"{100 * sum(saved[i] for i in idx) / len(idx):.1f} / "
                                     f"{100 * sum(fail[i] for i in idx) / len(idx):.1f}" if idx else "")
                    label = name if name == meth else f"{name} (same frames)"
                    out.append(f"| {rep['_label']} | {s['seed']} | {path} | {label} | " + " | ".join(cells) + " |")
    if not out:
        print("\n--by-age: no run played a method with prediction reuse (NAME@k, unseen tiles at 1x1, no "
              ":rS refresh)")
        return
    print("\nAt each method's default, work saved / failing tiles % by frames since the reuse method's network ran "
          "(0: it ran; the first frame, with no history, left out)\n")
    print("| map | seed | path | method | " + " | ".join(f"age {a}" for a in range(longest)) + " |")
    print("|---|---:|---|---|" + "---|" * longest)
    print("\n".join(out))


if __name__ == "__main__":
    run_main(main)
