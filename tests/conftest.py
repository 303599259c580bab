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
def fit_on_train(train_demos):
    """``fit_on_train(predictor, **options)``: a :class:`~cpmp.sequencer.ConcurrentSequencer`
    fitted on :func:`train_demos` with seed 0 and no logger (``options``: the predictor's and
    the sequencer's, as ``ConcurrentSequencer.fit`` takes them)."""
    from cpmp.sequencer import ConcurrentSequencer

    def fit(predictor: str = "klr", **options):
        return ConcurrentSequencer.fit(train_demos, predictor, seed=0, logger=None, **options)

    return fit


@pytest.fixture(scope="session")
def fitted_klr(fit_on_train):
    """The default ``klr`` sequencer fitted on :func:`train_demos`."""
    return fit_on_train("klr")
