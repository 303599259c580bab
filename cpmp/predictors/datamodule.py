"""The data of a progress-predictor fit as Lightning sees it: a ``LightningDataModule``.

A fit trains every node of every sequence graph at once, so a batch is not a set of samples
but, per node, a set of rows of that node's data (:class:`~cpmp.predictors.NodeData`, built by
:func:`cpmp.sequencer.fit_data.node_training_data` from the training demonstrations and by
:func:`cpmp.sequencer.fit_data.node_validation_data` from the validation ones). The node data
themselves stay in memory, on the module's device (:class:`~cpmp.predictors.lightning.
ProgressModule` moves them once); the loaders serve row indices, which Lightning moves with
each batch.

The loaders are plain iterables of index batches (Lightning takes any iterable), not torch
``DataLoader``s: there is nothing to load, so there is nothing for loader workers to do, and
no process, sampler or random state of a ``DataLoader`` is involved.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import lightning as L
import numpy as np
import torch

from cpmp.errors import ConfigError
from cpmp.predictors.base import NodeData

NodeRows = list[torch.Tensor]
"""One batch: per node, the rows ``(b_i,)`` (int64) of its data the step uses."""


class TrainBatches:
    """An epoch's training batches of per-node rows (an iterable Lightning takes as a loader).

    With ``batch_size=None`` an epoch is one batch of every row of every node (full batch).
    Otherwise an epoch has ``ceil(max_i P_i / batch_size)`` batches; node ``i``'s rows are
    shuffled each epoch and dealt out ``ceil(P_i / n_batches)`` per batch, a node with fewer
    rows than that starting its rows again, so that every batch holds at least one and at
    most ``batch_size`` rows of every node.
    """

    def __init__(
        self,
        sizes: Sequence[int],
        batch_size: int | None = None,
        generator: torch.Generator | None = None,
    ) -> None:
        """Batches over nodes of ``sizes`` rows each.

        Args:
            sizes: ``P_i``, the rows of each node (>= 1 each).
            batch_size: rows per node and batch at most (``None``: all, one batch).
            generator: where the shuffles are drawn from (required with ``batch_size``).

        Raises:
            ConfigError: a node without rows, or mini-batches without a generator.
        """
        if any(int(n) < 1 for n in sizes):
            raise ConfigError("every node needs at least one training sample")
        if batch_size is not None and generator is None:
            raise ConfigError("shuffled mini-batches need a generator")
        self.sizes = [int(n) for n in sizes]
        self.batch_size = batch_size
        self.generator = generator

    def __len__(self) -> int:
        if self.batch_size is None:
            return 1
        return math.ceil(max(self.sizes) / self.batch_size)

    def __iter__(self) -> Iterator[NodeRows]:
        if self.batch_size is None:
            yield [torch.arange(n) for n in self.sizes]
            return
        n_batches = len(self)
        orders = [torch.randperm(n, generator=self.generator) for n in self.sizes]
        per_batch = [math.ceil(n / n_batches) for n in self.sizes]
        for j in range(n_batches):
            yield [
                order[torch.arange(j * b, (j + 1) * b) % len(order)]
                for order, b in zip(orders, per_batch, strict=True)
            ]


class ValBatches:
    """The validation batches of per-node rows: every row once, in order.

    With ``batch_size`` set, ``ceil(max_i P_i / batch_size)`` batches split each node's rows
    into nearly equal consecutive chunks (a chunk may be empty); else one batch of all rows.
    """

    def __init__(self, sizes: Sequence[int], batch_size: int | None = None) -> None:
        """Batches over nodes of ``sizes`` rows each (>= 0 each, one > 0).

        Args:
            sizes: ``P_i``, the rows of each node.
            batch_size: rows per node and batch at most (``None``: all, one batch).
        """
        self.sizes = [int(n) for n in sizes]
        self.batch_size = batch_size

    def __len__(self) -> int:
        if not any(self.sizes):
            return 0
        if self.batch_size is None:
            return 1
        return math.ceil(max(self.sizes) / self.batch_size)

    def __iter__(self) -> Iterator[NodeRows]:
        chunks = [torch.tensor_split(torch.arange(n), len(self)) for n in self.sizes]
        for j in range(len(self)):
            yield [c[j] for c in chunks]


@dataclass(frozen=True)
class HeldOutSplit:
    """Which demonstrations train and which validate a fit.

    Attributes:
        train: indices of the training demonstrations, in their given order.
        val: indices of the held-out ones, in their given order.
    """

    train: list[int]
    val: list[int]


def held_out_split(n: int, fraction: float, seed: int) -> HeldOutSplit:
    """Hold out ``round(fraction · n)`` of ``n`` demonstrations (at least one) for validation.

    Args:
        n: the number of demonstrations.
        fraction: the share to hold out, in (0, 1).
        seed: which ones (a NumPy generator seeded with it draws them).

    Returns:
        The split; both parts keep the demonstrations' order.

    Raises:
        ConfigError: no demonstration would be left to train on.
    """
    n_val = max(1, round(fraction * n))
    if n_val >= n:
        raise ConfigError(
            f"val_fraction={fraction} holds out {n_val} of {n} demonstrations, leaving none "
            "to train on: lower it, give more demonstrations, or give validation "
            "demonstrations instead"
        )
    val = sorted(np.random.default_rng(seed).choice(n, size=n_val, replace=False).tolist())
    return HeldOutSplit([i for i in range(n) if i not in val], val)


class ProgressDataModule(L.LightningDataModule):
    """Training and validation data of one fit of a predictor bank (every node at once).

    ``train_dataloader`` serves the training batches (:class:`TrainBatches`: full batch, or
    mini-batches of ``batch_size`` rows per node reshuffled each epoch from ``generator``);
    ``val_dataloader`` the validation data in order (:class:`ValBatches`). Without
    validation data the trainer runs no validation loop (``limit_val_batches=0``).
    """

    def __init__(
        self,
        train: list[NodeData],
        val: list[NodeData] | None = None,
        batch_size: int | None = None,
        generator: torch.Generator | None = None,
    ) -> None:
        """Serve ``train`` and ``val``.

        Args:
            train: every node's training data, in the bank's node order.
            val: every node's validation data in the same order (a node may have none:
                zero rows), or ``None``.
            batch_size: rows per node and training step at most (``None``: full batch).
            generator: the generator of the shuffles (required with ``batch_size``).
        """
        super().__init__()
        self.train = train
        self.val = val if val and any(node.n_samples for node in val) else None
        self.batch_size = batch_size
        self.generator = generator
        if self.val is not None and len(self.val) != len(train):
            raise ConfigError(
                f"validation data has {len(self.val)} nodes, training data {len(train)}"
            )

    def train_dataloader(self) -> TrainBatches:
        """The training batches of one epoch."""
        sizes = [node.n_samples for node in self.train]
        return TrainBatches(sizes, self.batch_size, self.generator)

    def val_dataloader(self) -> ValBatches:
        """The validation batches (empty without validation data)."""
        sizes = [] if self.val is None else [node.n_samples for node in self.val]
        return ValBatches(sizes, self.batch_size)
