"""What ``rtp play`` writes and says: play.md's tables, its figures and GIF, its output folder, its help and
Ctrl-C account (the closed loop itself: test_play.py)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rtp import sdk
from rtp.cli import main as rtp_main
from rtp.evaluate import PlayReport, _play, play, plots
from rtp.evaluate._play import FAIL_LEVELS

pytestmark = pytest.mark.gl
W, H = 64, 48
KW: dict[str, Any] = {"frames": 3, "size": (W, H), "sweep": False, "flip_every": 0}


def _report(**settings: Any) -> PlayReport:
    return PlayReport({"scene": "procedural:0", "frames": 8, "fps": 60.0, "seed": 0, "size": [W, H], "tile_size": 16,
                       "fail_metric": "jnyang", "fail_threshold": 0.25, "flip_every": 0, **settings})


def _figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    figures: list[Any] = []
    monkeypatch.setattr(plots, "figure_image", lambda fig: figures.append(fig) or np.zeros((1, 1, 3), np.uint8))
    return figures


def test_the_worst_frames_table_keeps_a_saving_of_zero() -> None:
    """play.md's "worst 5% of frames" table left out a method whose value was exactly 0 (`value or nan`)."""
    rep = _report()
    rep.unseen["slow"] = [1.0] + [0.0] * 7
    for method, low in (("full", 0.0), ("jnyang", 0.4), ("older", None)):  # (a path kept by an older run: none)
        rep.matched += [{"path": "slow", "method": method, "fail_share": f, "work_saved": 0.5, "capped": False,
                         "work_saved_p05": low} for f in FAIL_LEVELS]
    table = rep.to_markdown().split("The worst 5% of frames")[1].split("Every run")[0]
    assert "| full | 0.0% | 0.0% | 0.0% |" in table and "| jnyang | 40.0% | 40.0% | 40.0% |" in table
    assert "older" not in table


def test_the_worst_frames_table_keeps_a_method_that_never_fails_that_rarely() -> None:
    """A method whose sweep never fails as rarely as 5% reads "-" at every share of the matched table, and was left
    out of the worst 5% of frames' table altogether (its worst frames' saving is unreadable there too): the two tables
    named different methods. It reads "-" in both; a path kept by an older run (a saving, no worst frames') stays
    out."""
    rep = _report()
    rep.unseen["fast"] = [1.0] + [0.0] * 7
    nan = float("nan")
    for method, saved, low in (("jnyang@4", [nan] * 3, [nan] * 3), ("jnyang", [0.5, 0.6, 0.7], [0.4, 0.5, 0.6]),
                               ("yang2019", [nan, nan, 0.3], [nan, nan, 0.2]), ("older", [0.5] * 3, [None] * 3)):
        rep.matched += [{"path": "fast", "method": method, "fail_share": f, "work_saved": w, "capped": False,
                         "work_saved_p05": v} for f, w, v in zip(FAIL_LEVELS, saved, low)]
    md = rep.to_markdown()
    assert "| jnyang@4 | - | - | - |" in md.split("The worst 5% of frames")[0]
    table = md.split("The worst 5% of frames")[1].split("Every run")[0]
    assert [line.split(" | ")[0] for line in table.splitlines() if line.startswith("| ") and "---" not in line][1:] \
        == ["| jnyang@4", "| jnyang", "| yang2019"]
    assert "| jnyang@4 | - | - | - |" in table and "| yang2019 | - | - | 20.0% |" in table


def test_full_shows_no_flip_where_none_was_measured() -> None:
    """With --flip-every 0 (or fewer frames than it) no FLIP is measured, and full's row read 0.0000 where
    every other method's reads "-"; full's FLIP is 0 on the frames FLIP is measured."""
    rep = play("procedural:0", "full,oracle", paths=("fast",), plots=False, **KW)
    full = next(r for r in rep.rows if r["method"] == "full")
    assert np.isnan(full["flip_mean"]) and "| full | **1x1** | 0.0% | 0.0% | 0.00% | - |" in rep.to_markdown()
    measured = play("procedural:0", "full,oracle", paths=("fast",), plots=False, **{**KW, "flip_every": 2})
    assert measured.frames["fast"]["full"]["flip"][1:] == [pytest.approx(np.nan, nan_ok=True), 0.0]
    assert "| full | **1x1** | 0.0% | 0.0% | 0.00% | 0.0000 |" in measured.to_markdown()


def test_the_curves_name_the_side_on_which_tiles_fail(monkeypatch: pytest.MonkeyPatch) -> None:
    """play_curves.png's axis read "tiles failing (psnr > 35)": PSNR's tiles fail at or under the threshold."""
    figures = _figures(monkeypatch)
    for metric, threshold in (("psnr", 35.0), ("jnyang", 0.25)):
        rep = _report(fail_metric=metric, fail_threshold=threshold)
        rep.unseen["fast"] = [1.0, 0.0, 0.0]
        rep.rows.append({"path": "fast", "method": "oracle", "fail_share": 0.0, "work_saved": 0.5, "default": True})
        plots.play_curves(rep)
    assert [f.axes[0].get_xlabel() for f in figures] == ["tiles failing (psnr ≤ 35), % (symlog)",
                                                          "tiles failing (jnyang ≥ 0.25), % (symlog)"]


def test_the_per_frame_failing_panel_names_its_threshold(monkeypatch: pytest.MonkeyPatch) -> None:
    """play_frames.png's failing panel read "tiles failing (jnyang), %": the metric but not the threshold over which a
    tile fails. It names both, on the failing side, as play_curves' axis does."""
    figures = _figures(monkeypatch)
    for metric, threshold in (("psnr", 35.0), ("jnyang", 0.3)):
        rep = _report(fail_metric=metric, fail_threshold=threshold, frames=3)
        rep.unseen["fast"] = [1.0, 0.0, 0.0]
        rep.frames["fast"] = {"oracle": {"saved": [0.5] * 3, "fail": [0.0] * 3, "change": [0.1] * 3}}
        plots.play_frames(rep)
    assert [f.axes[1].get_title() for f in figures] == ["fast: tiles failing (psnr ≤ 35), %",
                                                         "fast: tiles failing (jnyang ≥ 0.3), %"]


def test_the_gifs_rate_key_draws_each_swatch_as_the_figures_legend_and_the_sdks_key_do() -> None:
    """The GIF's colour key drew the 1x1 (untinted) swatch grey, the figures' rate legend white: one class, two
    colours. Each palette's key draws every swatch in rate_legend's colours, 1x1 plots.UNTINTED_SWATCH, the grey of
    the key draw_rate_overlay draws into a frame."""
    frame = sdk.draw_rate_overlay(np.zeros((40, 60, 3), np.float32), np.zeros((3, 4), np.uint8), 16, legend=True)
    np.testing.assert_array_equal(frame[40 - 33 + 4, 4], plots.UNTINTED_SWATCH)  # (the sdk key's first swatch)
    for palette in ("paper", "cvd"):
        key = _play._rate_key(200, 400, palette)
        rows = [label for label, _ in plots.rate_legend(palette)]
        step = min(200 // (len(rows) + 2), 28)
        font, left = max(6, round(step * 0.55)), step // 2
        for i, (_, colour) in enumerate(plots.rate_legend(palette), start=1):
            top = left + i * step
            want = [round(255 * c) for c in (plots.UNTINTED_SWATCH if colour is None else colour)]
            np.testing.assert_array_equal(key[top + font // 2, left + font // 2], want, err_msg=f"{palette} {i}")


def test_the_curves_show_a_point_that_fails_on_no_tile_whole(monkeypatch: pytest.MonkeyPatch) -> None:
    """play_curves.png's axis of failing tiles started at 0: the oracle's point (it fails on no tile) and its
    default's ring sat on the axis, half cut off. Every marker lies inside its panel."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    figures = _figures(monkeypatch)
    rep = _report()
    rep.unseen["fast"] = [1.0, 0.0, 0.0]
    rep.rows += [{"path": "fast", "method": "oracle", "fail_share": 0.0, "work_saved": 0.8, "default": True},
                 {"path": "fast", "method": "jnyang", "fail_share": 0.0, "work_saved": 0.4, "default": False},
                 {"path": "fast", "method": "jnyang", "fail_share": 0.05, "work_saved": 0.7, "default": True}]
    plots.play_curves(rep)
    (fig,) = figures
    FigureCanvasAgg(fig).draw()
    ax = fig.axes[0]
    marked = [line for line in ax.lines if line.get_marker() not in ("None", "", " ", None)]
    assert len(marked) == 4  # (two curves, two rings)
    for line in marked:
        r = line.get_markersize() * fig.dpi / 72 / 2
        for x, _ in ax.transData.transform(np.column_stack(line.get_data())):
            assert ax.bbox.x0 <= x - r and x + r <= ax.bbox.x1, (line.get_label(), x, r, ax.bbox)


def _drawn(ax: Any) -> set[float]:
    """The frames a panel's lines show: their markers' points, and both ends of each segment they draw."""
    xs: set[float] = set()
    for line in ax.lines:
        x, y = (np.asarray(v, np.float64) for v in line.get_data())
        ok = np.isfinite(y)
        if line.get_marker() not in ("None", "", " ", None):
            xs |= set(x[ok].tolist())
        if line.get_linestyle() not in ("None", "", " "):
            seg = ok[:-1] & ok[1:]
            xs |= set(x[:-1][seg].tolist()) | set(x[1:][seg].tolist())
    return xs


def test_the_rate_change_panel_draws_lone_values_and_leaves_frame_1_out(monkeypatch: pytest.MonkeyPatch) -> None:
    """Under --dynamic-resolution 1,0.5@2 every other frame's rate change is none (the tiles are others): a line
    drew none of the values between, and the panel was blank. It also drew frame 1's change, from frame 0's
    rates chosen without history, which the summary leaves out."""
    figures = _figures(monkeypatch)
    rep = _report(dynamic_resolution={"scales": [1.0, 0.5], "every": 2, "sizes": [[W, H], [W // 2, H // 2]]})
    rep.unseen["fast"] = [1.0] + [0.01] * 7
    nan = float("nan")
    rep.frames["fast"] = {"jnyang": {"saved": [0.5] * 8, "fail": [0.01] * 8,
                                     "change": [nan, 0.5, nan, 0.3, nan, 0.2, nan, 0.4]}}
    plots.play_frames(rep)
    (fig,) = figures
    panels = {ax.get_title(): ax for ax in fig.axes}
    assert _drawn(panels["fast: tiles whose rate changed, %"]) == {3.0, 5.0, 7.0}
    assert _drawn(panels["fast: work saved, %"]) == {float(i) for i in range(1, 8)}
    (legend,) = fig.legends  # (the dots are not a method of their own)
    assert [t.get_text() for t in legend.get_texts()] == ["jnyang"]


def test_the_per_frame_plot_of_a_short_run_counts_whole_frames(monkeypatch: pytest.MonkeyPatch) -> None:
    """A 3-frame run (the fewest --frames takes) drew its frame axes at 1.0, 1.2, ... 2.0 and its rate changes, one
    frame's, at 1.90 ... 2.10: fractions of a frame. Every frame axis is ticked at whole frames, one at the least."""
    figures = _figures(monkeypatch)
    rep = _report(frames=3)
    rep.unseen["slow"] = [1.0, 0.02, 0.01]
    rep.frames["slow"] = {"jnyang": {"saved": [0.5, 0.58, 0.54], "fail": [0.0, 0.23, 0.23],
                                     "change": [float("nan"), 0.4, 0.33]}}
    plots.play_frames(rep)
    (fig,) = figures
    fig.canvas.draw()
    for ax in fig.axes:
        lo, hi = ax.get_xlim()
        ticks = [t for t in ax.get_xticks() if lo <= t <= hi]
        assert ticks and all(float(t).is_integer() for t in ticks), (ax.get_title(), ticks)


def test_a_rate_change_never_measured_reads_as_a_dash() -> None:
    """Under --dynamic-resolution 1,0.5@1 every frame is drawn at another size than the one before, so no rate
    change is measured (the tiles are others): play.md's column read "nan%" where the FLIP column reads "-"."""
    rep = _report(dynamic_resolution={"scales": [1.0, 0.5], "every": 1, "sizes": [[W, H], [W // 2, H // 2]]})
    rep.unseen["fast"] = [1.0] + [0.01] * 7
    row = {"path": "fast", "method": "jnyang", "parameter": "threshold 0.25", "value": 0.25, "default": True,
           "work_saved": 0.5, "fail_share": 0.01, "flip_mean": float("nan"), "work_saved_p05": 0.4,
           "predict_ms": 1.0, "network_frames": 1.0}
    rep.rows += [{**row, "rate_change": float("nan")}, {**row, "parameter": "threshold 0.5", "default": False,
                                                          "rate_change": None}]  # (play.json writes NaN as null)
    md = rep.to_markdown()
    assert "nan" not in md
    assert "| jnyang | **threshold 0.25** | 50.0% | 40.0% | 1.00% | - | - | 1.00 | 100% |" in md
    assert "| jnyang | threshold 0.5 | 50.0% | 40.0% | 1.00% | - | - | 1.00 | 100% |" in md
    rep.rows[0]["rate_change"] = 0.25
    assert "| jnyang | **threshold 0.25** | 50.0% | 40.0% | 1.00% | - | 25.0% | 1.00 | 100% |" in rep.to_markdown()


def test_the_animation_leaves_out_the_first_frame(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Frame 0 has no history (every reprojection black: Yang 2019 coarse everywhere); the docs say it is left
    out of every figure, and the GIF showed it."""
    whens: list[str] = []
    real = _play._anim_frame
    monkeypatch.setattr(_play, "_anim_frame", lambda ref, shown, tile, when="", full=None, **kw:
                        whens.append(when) or real(ref, shown, tile, when, full, **kw))
    rep = play("procedural:0", "yang2019", paths=("fast",), out=tmp_path, **KW)
    assert [w.split(",")[0] for w in whens] == ["frame 1 of 3", "frame 2 of 3"]
    assert {"play_fast.gif", "play_fast.png"} <= set(rep.files)


_PLAY_PATH = _play._play_path


def _stop_on(monkeypatch: pytest.MonkeyPatch, path: str) -> None:
    """Ctrl-C as ``path`` starts (the paths before it played to their end)."""
    real = _PLAY_PATH

    def stopped(job: dict[str, Any], *rest: Any) -> dict[str, Any]:
        if job["path"] == path:
            raise KeyboardInterrupt
        return real(job, *rest)

    monkeypatch.setattr(_play, "_play_path", stopped)


def test_a_path_kept_without_its_animation_says_it_has_none(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            caplog: pytest.LogCaptureFixture) -> None:
    """A run with --no-animation (or --no-plots) stopped on its second path, resumed without it: the kept path
    never got its GIF and nothing said so. Its frames are not kept, so the resumed run says it writes none and
    how to have them; resumed the other way, the kept GIF goes (the run asked for none)."""
    kw = {**KW, "paths": ("slow", "fast")}
    real = _PLAY_PATH
    _stop_on(monkeypatch, "fast")
    with pytest.raises(KeyboardInterrupt):
        play("procedural:0", "oracle", out=tmp_path / "a", animation=False, **kw)
    monkeypatch.setattr(_play, "_play_path", real)
    with caplog.at_level(logging.WARNING, logger="rtp.evaluate"):
        rep = play("procedural:0", "oracle", out=tmp_path / "a", **kw)
    (warning,) = [r.getMessage() for r in caplog.records if "interrupted run" in r.getMessage()]
    assert warning.startswith(f"{tmp_path / 'a'}: path slow is read back from an interrupted run that left no "
                              "play_slow.gif or play_slow.png (it played with --no-animation")
    assert warning.endswith(f"this run writes none; delete {tmp_path / 'a' / '.play-slow.partial.json'} to play the "
                            "path again with them")
    assert "play_fast.gif" in rep.files and "play_slow.gif" not in rep.files
    assert not (tmp_path / "a" / "play_slow.gif").exists()

    _stop_on(monkeypatch, "fast")
    with pytest.raises(KeyboardInterrupt):
        play("procedural:0", "oracle", out=tmp_path / "b", **kw)
    assert (tmp_path / "b" / "play_slow.gif").is_file()
    monkeypatch.setattr(_play, "_play_path", real)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="rtp.evaluate"):
        rep = play("procedural:0", "oracle", out=tmp_path / "b", animation=False, **kw)
    assert "interrupted run" not in caplog.text
    assert not any(f.endswith(".gif") for f in rep.files) and not list((tmp_path / "b").glob("*.gif"))


def test_a_run_into_another_runs_folder_removes_that_runs_pictures(tmp_path: Path) -> None:
    """A slow run into a folder of a slow-and-fast run kept play_fast.gif and .png beside its report; a run
    without plots kept the curves. rtp play's own pictures that the new report does not list are removed; no
    other file is."""
    play("procedural:0", "oracle", paths=("slow", "fast"), out=tmp_path, **KW)
    for name in ("notes.txt", "play_medium.gif", "play_fast.jpg"):  # (not names rtp play gives its pictures)
        (tmp_path / name).write_text("mine")
    rep = play("procedural:0", "oracle", paths=("slow",), out=tmp_path, **KW)
    assert sorted(rep.files) == ["play.json", "play.md", "play_curves.png", "play_frames.png", "play_slow.gif",
                                 "play_slow.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(rep.files + ["notes.txt", "play_fast.jpg",
                                                                             "play_medium.gif"])
    rep = play("procedural:0", "oracle", paths=("slow",), out=tmp_path, plots=False, **KW)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "play.json", "play.md", "play_fast.jpg",
                                                         "play_medium.gif"]


def test_no_animation_says_it_drops_the_middle_frame_too(capsys: pytest.CaptureFixture[str]) -> None:
    """--no-animation's help said "no GIF"; it leaves out each path's middle frame, play_PATH.png, too."""
    with pytest.raises(SystemExit):
        rtp_main(["play", "--help"])
    shown = " ".join(capsys.readouterr().out.split())
    assert "--no-animation no GIF per path, nor its middle frame (play_PATH.gif and play_PATH.png;" in shown


def test_ctrl_c_says_which_paths_are_kept(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C on the first path said "the paths played to their end are kept in OUT" of none: it says none is,
    and otherwise names those that are (read back by the rerun too) and those left."""
    out = tmp_path / "p"
    run = ["play", "procedural:0", "--methods", "oracle", "--frames", "3", "--size", f"{W}x{H}", "--no-sweep",
           "--flip-every", "0", "--no-plots", "--out", str(out), "-q"]
    _stop_on(monkeypatch, "slow")
    assert rtp_main(run) == 130
    assert capsys.readouterr().err == (f"rtp play: interrupted; no path was played to its end, so none is kept in {out} "
                                       "(each is kept as it ends): the same command plays them all\n")
    _stop_on(monkeypatch, "fast")
    for _ in range(2):
        assert rtp_main(run) == 130
        assert capsys.readouterr().err == (f"rtp play: interrupted; the path played to its end (slow) is kept in {out}: "
                                           "the same command plays the rest (fast)\n")


def test_the_animation_draws_its_overlays_in_the_palette_asked_for(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                   capsys: pytest.CaptureFixture[str],
                                                                   caplog: pytest.LogCaptureFixture) -> None:
    """play(palette="cvd") and `rtp play --palette cvd` draw the GIFs' rate overlays and key in the colour-vision
    deficiency palette (the paper's by default); an unknown one is refused before any work, and with --no-animation or
    --no-plots, which draw no overlay, --palette cvd is refused. The palette changes only pictures, so it is not in
    the resume key: a path kept by an interrupted run in another palette is read back, not played again, its GIF
    kept in that palette and a warning saying so."""
    palettes: list[str] = []
    real = _play._anim_frame
    monkeypatch.setattr(_play, "_anim_frame", lambda *a, **kw: palettes.append(kw["palette"]) or real(*a, **kw))
    for palette in ("paper", "cvd"):
        play("procedural:0", "oracle", paths=("fast",), out=tmp_path / palette, palette=palette, **KW)
    assert palettes == ["paper"] * 2 + ["cvd"] * 2  # (frames 1 and 2 of 3)
    from PIL import Image

    stills = [np.asarray(Image.open(tmp_path / p / "play_fast.png").convert("RGB")) for p in ("paper", "cvd")]
    assert stills[0].shape == stills[1].shape and (stills[0] != stills[1]).any()
    key = {p: _play._rate_key(120, 300, p) for p in ("paper", "cvd")}
    assert (key["paper"] != key["cvd"]).any()
    cvd = tuple(round(255 * c) for c in sdk.OVERLAY_PALETTES["cvd"]["fine"])
    assert (key["cvd"] == cvd).all(-1).any() and not (key["paper"] == cvd).all(-1).any()

    with pytest.raises(_play.PlayError, match="palette: expected one of 'paper', 'cvd'"):
        play("no-such-map", "oracle", out=tmp_path / "bad", palette="grey", **KW)
    assert not (tmp_path / "bad").exists()

    # resumed in another palette: the kept path read back (not played again), its GIF kept, a warning
    kw = {**KW, "paths": ("slow", "fast")}
    _stop_on(monkeypatch, "fast")
    with pytest.raises(KeyboardInterrupt):
        play("procedural:0", "oracle", out=tmp_path / "r", **kw)
    played: list[str] = []
    monkeypatch.setattr(_play, "_play_path", lambda job, *rest: played.append(job["path"]) or _PLAY_PATH(job, *rest))
    palettes.clear()
    with caplog.at_level(logging.WARNING, logger="rtp.evaluate"):
        rep = play("procedural:0", "oracle", out=tmp_path / "r", palette="cvd", **kw)
    assert played == ["fast"] and palettes == ["cvd"] * 2
    assert {"play_slow.gif", "play_slow.png", "play_fast.gif"} <= set(rep.files)
    (warning,) = [r.getMessage() for r in caplog.records if "palette" in r.getMessage()]
    assert warning.startswith(f"{tmp_path / 'r'}: path slow is read back from an interrupted run that drew "
                              "play_slow.gif and play_slow.png in the 'paper' palette")
    assert warning.endswith(f"delete {tmp_path / 'r' / '.play-slow.partial.json'} to play the path again in it")

    # the command line: passed on, refused where nothing is drawn in it, an unknown one refused by argparse
    monkeypatch.setattr(_play, "_play_path", _PLAY_PATH)
    run = ["play", "procedural:0", "--methods", "oracle", "--frames", "3", "--size", f"{W}x{H}", "--no-sweep",
           "--flip-every", "0", "--path", "fast", "-q"]
    palettes.clear()
    assert rtp_main([*run, "--out", str(tmp_path / "cli"), "--palette", "cvd"]) == 0
    assert palettes == ["cvd"] * 2
    capsys.readouterr()
    for flag in ("--no-animation", "--no-plots"):
        assert rtp_main([*run, "--out", str(tmp_path / "none"), "--palette", "cvd", flag]) == 2
        assert f"--palette cvd: the colours of the GIFs' rate overlays, which {flag} leaves out" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        rtp_main([*run, "--out", str(tmp_path / "none"), "--palette", "grey"])
    assert stop.value.code == 2 and "--palette: invalid choice: 'grey'" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()
