"""bench/_common.py's helpers that are not argument types (those: tests/test_bench_errors.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from .conftest import bench_module


def test_a_figure_stopped_while_written_leaves_the_one_before(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """save_figure wrote into the figure's own path: a run stopped there (or a full disk) left half a PNG where docs/
    embeds the figure before; now the old file stays, and a finished one replaces it whole, in its format."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    common = bench_module("_common")
    out = tmp_path / "figs" / "plot.png"
    common.save_figure(plt.figure(), out)
    first = out.read_bytes()
    assert first.startswith(b"\x89PNG") and "wrote" in capsys.readouterr().out

    fig = plt.figure()

    def stopped(path: object, **kwargs: object) -> None:
        Path(str(path)).write_bytes(b"\x89PNG half")
        raise KeyboardInterrupt

    monkeypatch.setattr(fig, "savefig", stopped)
    with pytest.raises(KeyboardInterrupt):
        common.save_figure(fig, out)
    assert out.read_bytes() == first and sorted(p.name for p in out.parent.iterdir()) == ["plot.png"]
    assert not plt.fignum_exists(fig.number)  # (closed all the same)
    common.save_figure(plt.figure(), tmp_path / "plot.svg")
    assert b"<svg" in (tmp_path / "plot.svg").read_bytes()[:400]


def test_the_commands_a_dataset_error_tells_to_run_quote_the_path(tmp_path: Path) -> None:
    """dataset_folder's error names the capture and targets commands with the folder as given: `my data` was printed
    bare, and the command copied into a shell captured into `my` (shlex.split of it gives the path back now)."""
    import argparse
    import re
    import shlex

    common = bench_module("_common")
    folder = str(tmp_path / "my data")
    with pytest.raises(argparse.ArgumentTypeError) as err:
        common.dataset_folder(folder)
    [command] = re.findall(r"`(rtp capture [^`]*)`", str(err.value))
    argv = shlex.split(command)
    assert argv[argv.index("--out") + 1] == folder and argv[-1] == folder, argv
