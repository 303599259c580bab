"""Fixtures of the worlds' tests."""

from __future__ import annotations

import pytest

from cpmp.sequencer import ConcurrentSequencer


class OneAtATime:
    """A fitted sequencer without ``batched``: a world runs it one episode at a time."""

    def __init__(self, seq: ConcurrentSequencer) -> None:
        self.seq = seq

    def reset(self, t, x):
        return self.seq.reset(t, x)

    def step(self, t, x):
        return self.seq.step(t, x)


@pytest.fixture(scope="session")
def one_at_a_time() -> type[OneAtATime]:
    """Wraps a fitted sequencer so that a world cannot batch its episodes."""
    return OneAtATime
