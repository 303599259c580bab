"""Shared fixtures: small synthetic demonstrations and a fitted sequencer."""

from __future__ import annotations

import pytest
import torch

from cpmp.synthetic import make_demonstrations

# One thread: on 2 cores, torch's default thread pool fights with other processes and makes
# the small fits of the tests many times slower.
torch.set_num_threads(1)


@pytest.fixture(scope="session")
def train_demos():
    """Six synthetic two-variable demonstrations, three per strategy."""
    return make_demonstrations(6, seed=0)


@pytest.fixture(scope="session")
def test_demos():
    """Held-out synthetic demonstrations from another seed."""
    return make_demonstrations(6, seed=1)


@pytest.fixture(scope="session")
def fitted_klr(train_demos):
    from cpmp.sequencer import ConcurrentSequencer

    return ConcurrentSequencer.fit(train_demos, predictor="klr", seed=0, logger=None)
