"""The policies the simulator's closed loop drives, and how they are batched.

:func:`~cpmp.sim.runner.run_episodes` drives one :class:`~cpmp.records.BatchedPolicy` for all
its boxes: :func:`as_batched` makes one from whatever it is given (:class:`PolicyList` wraps
single policies). :class:`ReplayPolicy` replays a recorded demonstration's labels.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TypeVar

import numpy as np

from cpmp.data.demonstration import Demonstration
from cpmp.errors import ConfigError
from cpmp.records import BatchedPolicy, Policy

T = TypeVar("T")


class PolicyList:
    """N single :class:`Policy` objects as one :class:`BatchedPolicy`.

    Each live episode's policy is called in turn with its own row of ``x``.
    """

    def __init__(self, policies: Sequence[Policy]) -> None:
        self.policies = list(policies)

    def __len__(self) -> int:
        return len(self.policies)

    def reset(
        self, t: float, x: np.ndarray, live: np.ndarray | None = None
    ) -> list[Mapping[str, str]]:
        """Each live episode's policy ``reset`` on its row of ``x`` (N, d)."""
        return self._call("reset", t, x, live)

    def step(
        self, t: float, x: np.ndarray, live: np.ndarray | None = None
    ) -> list[Mapping[str, str]]:
        """Each live episode's policy ``step`` on its row of ``x`` (N, d)."""
        return self._call("step", t, x, live)

    def _call(
        self, name: str, t: float, x: np.ndarray, live: np.ndarray | None
    ) -> list[Mapping[str, str]]:
        return [
            getattr(policy, name)(t, row) if live is None or live[i] else {}
            for i, (policy, row) in enumerate(zip(self.policies, x, strict=True))
        ]


class ReplayPolicy:
    """Replays a demonstration's labels by time (open-loop).

    A reference policy for tests and benchmarks: ``reset``/``step`` return the labels of the
    sample at or before ``t``.
    """

    def __init__(self, demo: Demonstration) -> None:
        self.time = np.asarray(demo.time)
        self.labels = {v: np.asarray(lab) for v, lab in demo.labels.items()}

    def _at(self, t: float) -> dict[str, str]:
        i = int(np.clip(np.searchsorted(self.time, t + 1e-9) - 1, 0, len(self.time) - 1))
        return {v: str(lab[i]) for v, lab in self.labels.items()}

    def reset(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The labels at time ``t`` [s] (``x`` is not read)."""
        return self._at(t)

    def step(self, t: float, x: np.ndarray) -> dict[str, str]:
        """The labels at time ``t`` [s] (``x`` is not read)."""
        return self._at(t)


def per_episode(values: Sequence[T] | None, n: int, name: str) -> list[T | None]:
    """``values`` as a list of ``n`` (``None``: ``n`` times ``None``)."""
    if values is None:
        return [None] * n
    values = list(values)
    if len(values) != n:
        raise ConfigError(f"{name} must hold one entry per box ({n}), got {len(values)}")
    return values


def as_batched(policy: Policy | BatchedPolicy | Sequence[Policy], n: int) -> BatchedPolicy:
    """The batched policy :func:`run_episodes` drives for ``n`` boxes."""
    if isinstance(policy, Sequence):
        batch: BatchedPolicy = PolicyList(policy)
    elif hasattr(policy, "batched"):
        batch = policy.batched(n)
    elif hasattr(policy, "n_episodes") or isinstance(policy, PolicyList):
        batch = policy
    elif n == 1:
        batch = PolicyList([policy])
    else:
        raise ConfigError(
            f"run_episodes needs one policy per box ({n}), a batched policy of {n} episodes or "
            "a policy with batched(n) (a ConcurrentSequencer); got one single-episode policy"
        )
    if len(batch) != n:
        raise ConfigError(f"the batched policy runs {len(batch)} episodes, there are {n} boxes")
    return batch
