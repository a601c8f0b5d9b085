"""bench/inference.py: the models are timed in rounds, each once a round, so that a ratio within a round
compares two models under the same conditions."""

from __future__ import annotations

from .conftest import bench_module


def test_interleaved_runs_every_model_once_a_round_after_a_warm_up_round() -> None:
    mod = bench_module("inference")
    calls: list[str] = []
    runs = {name: (lambda name=name: calls.append(name)) for name in ("paper", "a", "b")}
    times = mod.interleaved_ms(runs, 3)
    assert calls == ["paper", "a", "b"] * 4  # the warm-up round, then three rounds, in turn
    assert {k: len(v) for k, v in times.items()} == {"paper": 3, "a": 3, "b": 3}
    assert all(t >= 0 for v in times.values() for t in v)
