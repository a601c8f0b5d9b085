"""Fuzz the runtime and the dataset reader with generated malformed inputs and print a table.

    python bench/fuzz.py                 # 1,000 inputs per target (23 targets: 23,000 inputs)
    python bench/fuzz.py --per-target 200 --show 3

The inputs and targets are tests/fuzzing.py's (tests/test_fuzz.py runs fewer of them in CI). Every
refusal must be an rtp.sdk.RtpError ("typed"); "untyped" counts other exceptions escaping (bugs) and
"absurd accepted" inputs that make no sense but were accepted. Both must be 0.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import count, positive, run_main  # noqa: E402  # bench/ is on sys.path when run as a script
from hypothesis import HealthCheck, given, settings  # noqa: E402

from tests.fuzzing import OUTCOMES, Target, classify, targets  # noqa: E402


def _fuzz(target: Target, counts: Counter[str], bad: list[tuple[str, ...]], n: int) -> None:
    @settings(max_examples=n, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(target.strategy)
    def run(value: object) -> None:
        outcome, err = classify(target, value)
        counts[outcome] += 1
        if outcome in ("untyped", "absurd accepted") and len(bad) < 50:
            bad.append((target.name, outcome, repr(value)[:160], f"{type(err).__name__}: {err}"[:200]))

    run()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--per-target", type=positive, default=1000, help="generated inputs per target")
    ap.add_argument("--show", type=count, default=2, help="examples of untyped or absurd-accepted inputs to print")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    rows, bad = [], []
    for target in targets():
        counts: Counter[str] = Counter()
        t0 = time.perf_counter()
        _fuzz(target, counts, bad, args.per_target)
        rows.append((target.name, sum(counts.values()), *[counts[o] for o in OUTCOMES], time.perf_counter() - t0))
    print("| target | inputs | " + " | ".join(OUTCOMES) + " | s |")
    print("|---|---:|" + "---:|" * (len(OUTCOMES) + 1))
    for name, n, *cells, secs in rows:
        print(f"| {name} | {n} | " + " | ".join(str(c) for c in cells) + f" | {secs:.1f} |")
    total = [sum(r[i] for r in rows) for i in range(1, 2 + len(OUTCOMES))]
    print("| **all** | " + " | ".join(f"**{t}**" for t in total) + " | |")
    for name, outcome, value, err in bad[: args.show * len(rows)]:
        print(f"\n{outcome}: {name}\n  input: {value}\n  {err}")
    sys.exit(1 if total[OUTCOMES.index("untyped") + 1] or total[OUTCOMES.index("absurd accepted") + 1] else 0)


if __name__ == "__main__":
    run_main(main)
