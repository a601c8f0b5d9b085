"""Property-based fuzzing of the runtime and the dataset reader (hypothesis): whatever malformed
model file, metadata, sidecar, array, threshold or dataset file arrives, rtp either accepts it (when
it makes sense) or refuses it with an rtp.sdk.RtpError; nothing else escapes and nothing absurd is
accepted. bench/fuzz.py runs the same targets at scale and prints the counts (docs/runtime.md)."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings

from .fuzzing import classify, scaled, targets

TARGETS = targets()


@pytest.mark.parametrize("target", TARGETS, ids=[t.name for t in TARGETS])
def test_malformed_inputs_are_typed_errors_and_nothing_absurd_is_accepted(target: object) -> None:
    @settings(max_examples=scaled(150), deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(target.strategy)  # type: ignore[attr-defined]
    def run(value: object) -> None:
        outcome, err = classify(target, value)  # type: ignore[arg-type]
        assert outcome not in ("untyped", "absurd accepted"), f"{outcome} for {value!r}: {err!r}"

    run()
