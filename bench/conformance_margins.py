"""Measure the margins of the conformance kit's previous-frame checks (docs/adapters.md "Testing an adapter").

    python bench/conformance_margins.py [--levels 0-4] [--sizes 64x48,320x192]

Runs ``rtp.conformance.check_adapter`` on the procedural level of each seed of ``--levels`` at each of
``--sizes``, for three adapters: the pyrender adapter as shipped (pyrender's lit image as the previous
frame), the same adapter handed its previous frame upside down (a GL texture's rows, bottom first; its
depth the right way up), and the same adapter without the depth test (a disocclusion test that never
fails: a relative depth tolerance of 1, so every pixel that reprojects inside the previous frame is
seen). Each check's own text gives the numbers: the correlation of the gradient magnitudes of the
adapter's reprojected luma with the reference renderer's (``MIN_EDGE_CORRELATION``), and the share of the
pixels the previous frame hid that the adapter leaves unseen (``MIN_OCCLUDED_UNSEEN``, "NN% of M": M
hidden pixels). Prints a markdown table of both per level, size and adapter, then their range per
adapter beside the kit's thresholds: the margins docs/adapters.md and conformance/_kit.py quote.
A cell reads "skipped" where the kit skipped the check (a move that hides fewer than 5 pixels).
"""

from __future__ import annotations

import argparse
import os
import re
from typing import Any

import numpy as np
from _common import frame_sizes, run_main  # bench/ is on sys.path when run as a script

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

EDGES = "the previous frame's edges line up with the reference renderer's"
HIDDEN = "pixels the previous frame hid are unseen (the depth test)"
# the check's note where it passed ("correlation 0.77", "100% of 7") and its message where it failed
# ("... correlate 0.26 with the reference's ...", "27% of the 134 pixels the previous frame hid ...")
CORRELATION = re.compile(r"correlat(?:ion|e) (-?\d+\.\d+)")
SHARE = re.compile(r"(\d+)% of (?:the )?(\d+)")


def levels(text: str) -> list[int]:
    """An argparse type: procedural seeds, comma-separated integers >= 0 or ranges ``A-B`` (``0-4``, ``0,2-3``),
    each once."""
    out: list[int] = []
    for part in text.split(","):
        m = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
        if not m or (m[2] is not None and int(m[2]) < int(m[1])):
            raise argparse.ArgumentTypeError(f"expected comma-separated seeds >= 0 or ranges A-B with A <= B "
                                             f"(such as 0-4 or 0,2,3), got {text!r}")
        out += range(int(m[1]), int(m[2] if m[2] is not None else m[1]) + 1)
    twice = sorted({v for v in out if out.count(v) > 1})
    if twice:
        raise argparse.ArgumentTypeError(f"each level once, got {', '.join(map(str, twice))} more than once in {text!r}")
    return out


def variants() -> dict[str, type]:
    """The pyrender adapter as shipped, and the two broken ones the previous-frame checks must catch."""
    from rtp.plugins.pyrender import Adapter

    class PrevUpsideDown(Adapter):
        """The previous frame handed to ``sdk.input_planes`` upside down (a GL read-back's row order)."""

        def _frame(self, image: Any, name: str) -> np.ndarray:  # (the adapter's check of prev_colour: private)
            a = super()._frame(image, name)
            return np.ascontiguousarray(a[::-1]) if name == "prev_colour" else a

    class NoDepthTest(Adapter):
        """A disocclusion test that never fails: ``sdk.input_planes(tolerance=1.0)`` (a depth behind the
        previous frame's is within 100 %)."""

        def __init__(self, *args: Any, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.reprojection_tolerance = 1.0

    return {"shipped": Adapter, "upside down": PrevUpsideDown, "no depth test": NoDepthTest}


def measure(cls: type, level: int, size: tuple[int, int]) -> tuple[Any, Any]:
    """The two previous-frame checks of ``check_adapter(cls)`` on ``procedural:<level>`` at ``size``."""
    from rtp.conformance import check_adapter

    report = check_adapter(cls, size=size, scene=f"procedural:{level}")
    if report.not_run:
        from _common import UsageError

        raise UsageError(f"the conformance checks did not draw: {report.not_run}")
    found = {c.name: c for c in report.checks if c.group == "previous frame"}
    return found.get(EDGES), found.get(HIDDEN)


def cell(check: Any, pattern: re.Pattern[str]) -> tuple[str, float | None]:
    """The table's text for one check and the number it measured (None where skipped or missing)."""
    if check is None:
        return "not run", None
    m = pattern.search(check.detail)
    if check.status == "skipped" or m is None:
        return (f"skipped ({check.detail})" if check.status == "skipped" else f"{check.status}: {check.detail}"), None
    mark = "" if check.status == "passed" else " (fails)"
    if pattern is CORRELATION:
        return f"{float(m[1]):.2f}{mark}", float(m[1])
    return f"{m[1]}% of {m[2]}{mark}", int(m[1]) / 100


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--levels", type=levels, default=list(range(5)),
                    help="procedural seeds, comma-separated or ranges A-B (default 0-4)")
    ap.add_argument("--sizes", type=frame_sizes(16), default=[(64, 48), (320, 192)],
                    help="comma-separated WIDTHxHEIGHT, at least 16x16 (default 64x48,320x192)")
    args = ap.parse_args()
    from rtp.conformance import MIN_EDGE_CORRELATION, MIN_OCCLUDED_UNSEEN
    from rtp.plugins.pyrender import import_pyrender

    import_pyrender()  # (pyrender missing, or no headless GL: one line before the table)
    adapters = variants()
    print(f"conformance margins of the previous-frame checks, pyrender adapter; levels "
          f"{', '.join(map(str, args.levels))}; kit thresholds: edge correlation >= {MIN_EDGE_CORRELATION}, "
          f"hidden pixels unseen >= {MIN_OCCLUDED_UNSEEN:.0%}\n")
    print("| level | size | " + " | ".join(f"{v}: edge correlation | {v}: hidden unseen" for v in adapters) + " |")
    print("|---:|---|" + "---:|---:|" * len(adapters))
    seen: dict[str, tuple[list[float], list[float]]] = {v: ([], []) for v in adapters}
    for level in args.levels:
        for w, h in args.sizes:
            cells = []
            for v, cls in adapters.items():
                edges, hidden = measure(cls, level, (w, h))
                for check, pattern, values in ((edges, CORRELATION, seen[v][0]), (hidden, SHARE, seen[v][1])):
                    text, value = cell(check, pattern)
                    cells.append(text)
                    if value is not None:
                        values.append(value)
            print(f"| {level} | {w}x{h} | " + " | ".join(cells) + " |", flush=True)

    def span(values: list[float], fmt: str) -> str:
        return f"{min(values):{fmt}} to {max(values):{fmt}} ({len(values)})" if values else "none measured"

    print("\n| adapter | edge correlation, min to max (checks measured) | hidden pixels unseen, min to max (checks measured) |")
    print("|---|---:|---:|")
    for v, (r, share) in seen.items():
        print(f"| {v} | {span(r, '.2f')} | {span(share, '.0%')} |")
    print(f"| kit threshold | >= {MIN_EDGE_CORRELATION} (MIN_EDGE_CORRELATION) | "
          f">= {MIN_OCCLUDED_UNSEEN:.0%} (MIN_OCCLUDED_UNSEEN) |")


if __name__ == "__main__":
    run_main(main)
