"""Common machinery of the progress predictors.

A predictor is one :class:`torch.nn.Module` holding the progress models of *all* nodes of all
sequence graphs (a "bank"), so that one call evaluates every node:
``forward(x: (..., d)) -> (..., K)`` progress in [0, 1] for the K nodes in ``node_keys`` order.
Training data comes per node as :class:`NodeData`; banks fit all nodes in one optimisation.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from cpmp.config.predictors import SCALINGS, PredictorConfig  # noqa: F401 (re-exported)
from cpmp.config.trainer import SolverOptions
from cpmp.errors import ConfigError, DataError
from cpmp.predictors.newton import NewtonInfo
from cpmp.progress import denoise_trajectory
from cpmp.records import JsonValue

NodeKey = tuple[str, str]
"""(control variable, MP name)."""


@dataclass
class NodeData:
    """Training data of one node, in the predictor's (scaled) feature space.

    Attributes:
        key: (variable, MP).
        x: (P, d) feature samples of all activations of the node.
        target: (P,) expected progress (eq. 1) of each sample.
        activations: the node's activations as separate (n_j, d) trajectories.
        paths: the same activations as eq. 1 measures them (n_j, d): denoised once per fit
            (:func:`cpmp.progress.path_trajectory`) for a bank with ``path_denoised``
            labels, the ``activations`` themselves otherwise, with the ``ignored`` features
            held at their first value; support points and feature weights are placed along
            these.
        labels: each activation's progress labels (n_j,), of which ``target`` keeps a
            subsample.
        ignored: ``(d,)`` bool, the features eq. 1 leaves out (the ambient drift, not the
            task's motion; :func:`cpmp.sequencer.motion.ambient_features`): a path-weighted
            kernel gives them weight 0. ``None``: none.
    """

    key: NodeKey
    x: torch.Tensor
    target: torch.Tensor
    activations: list[np.ndarray] = field(default_factory=list)
    paths: list[np.ndarray] = field(default_factory=list)
    labels: list[np.ndarray] = field(default_factory=list)
    ignored: np.ndarray | None = None

    @property
    def n_samples(self) -> int:
        """Training samples ``P`` of the node."""
        return int(self.x.shape[0])

    def to(self, device: torch.device | str) -> NodeData:
        """This node's data with ``x`` and ``target`` on ``device``.

        Args:
            device: the torch device the bank is on.

        Returns:
            ``self`` when both tensors are there already, else a copy holding the moved
            tensors (the NumPy fields are shared).
        """
        x, target = self.x.to(device), self.target.to(device)
        if x is self.x and target is self.target:
            return self
        return dataclasses.replace(self, x=x, target=target)


def nodes_to(data: list[NodeData], device: torch.device | str) -> list[NodeData]:
    """Every node's data on ``device`` (:meth:`NodeData.to`).

    Args:
        data: per-node data.
        device: the torch device the bank is on.

    Returns:
        ``data`` itself when nothing had to move (so that a bank's per-list caches still
        apply), else a new list.
    """
    moved = [node.to(device) for node in data]
    return data if all(a is b for a, b in zip(moved, data, strict=True)) else moved


class FeatureScaler(nn.Module):
    """Affine feature scaling ``(x - offset) / scale`` fitted on training data.

    * ``global`` (default): every feature minus its training minimum, divided by *one* common
      factor, the largest per-feature training range. The features keep the relative
      geometry their designer gave them (the paper scales its features to about [0, 1] itself)
      while a change of units of all features (m -> mm) no longer changes the model.
    * ``none``: features as they are (the paper).
    * ``minmax``: each feature's training range to [0, 1]; ``standard``: each feature to zero
      mean and unit std. Per-feature scaling suits features in mixed units, but it also blows
      up features that barely vary (sensor noise on a near-constant coordinate) until they
      dominate the kernel.

    Constant features get scale 1. With ``noise="auto"`` the ranges (and moments) are those
    of :func:`cpmp.progress.denoise_trajectory` of the samples, so that white noise on the
    training features does not widen them (and with them shrink every path length, hence
    the support counts, and the kernel's reach); an extreme held for only m samples comes out
    lower by about the denoising penalty / m.
    """

    def __init__(
        self, n_features: int, dtype: torch.dtype = torch.float64, noise: str = "none"
    ) -> None:
        super().__init__()
        self.noise = noise
        self.register_buffer("offset", torch.zeros(n_features, dtype=dtype))
        self.register_buffer("scale", torch.ones(n_features, dtype=dtype))

    def fit(self, x: np.ndarray, mode: str) -> None:
        """Fit on training samples.

        Args:
            x: ``(N, d)`` samples in recording order (demonstrations one after the other).
            mode: the scaling, one of :data:`~cpmp.config.SCALINGS`.
        """
        if mode == "none":
            return
        if self.noise == "auto":
            x = denoise_trajectory(x)
        if mode == "global":
            lo = x.min(axis=0)
            offset, scale = lo, np.full(x.shape[1], np.max(x.max(axis=0) - lo))
        elif mode == "minmax":
            lo, hi = x.min(axis=0), x.max(axis=0)
            offset, scale = lo, hi - lo
        else:
            offset, scale = x.mean(axis=0), x.std(axis=0)
        magnitude = float(np.max(np.abs(x), initial=0.0))
        scale = np.where((scale > 0) & (scale > 1e-12 * magnitude), scale, 1.0)
        self.offset.copy_(torch.as_tensor(offset, dtype=self.offset.dtype))
        self.scale.copy_(torch.as_tensor(scale, dtype=self.scale.dtype))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Scaled features ``(..., d)`` of ``x (..., d)``."""
        return (x - self.offset) / self.scale

    def transform(self, x: np.ndarray) -> np.ndarray:
        """NumPy version of :meth:`forward`: ``(..., d) -> (..., d)``."""
        return (x - self.offset.numpy(force=True)) / self.scale.numpy(force=True)


class ProgressPredictor(nn.Module):
    """A bank of per-node progress predictors evaluated together.

    Subclasses implement :meth:`logits` (on scaled features), :meth:`initialize` (data-dependent
    set-up such as support points) and :meth:`training_loss`. A bank whose training loss is
    convex in its trainable parameters sets ``convex = True`` and implements
    :meth:`solve_convex`; the others are trained by Adam.
    """

    kind: ClassVar[str] = ""
    config_class: ClassVar[type[PredictorConfig]] = PredictorConfig
    convex: ClassVar[bool] = False
    labels: str = "path"
    """Training labels (:data:`cpmp.progress.LABELS`): ``path`` (eq. 1) or ``time``; a bank
    with ``path`` labels and ``config.path_noise == "auto"`` trains on ``path_denoised``."""
    stateful: ClassVar[bool] = False
    """A stateful bank treats the rows of each forward call as :meth:`reset_state`'s
    ``n_streams`` independent streams, each advancing one tick per call (e.g. ``dtw``, which
    aligns a window of recent features); feed such a bank one tick at a time."""

    def __init__(self, node_keys: list[NodeKey], n_features: int, config: PredictorConfig) -> None:
        super().__init__()
        if not node_keys:
            raise ConfigError("a predictor needs at least one node")
        if n_features < 1:
            raise ConfigError(f"n_features must be >= 1, got {n_features}")
        self.node_keys = [tuple(k) for k in node_keys]
        self.n_features = n_features
        self.config = config
        if self.labels == "path" and config.path_noise == "auto":
            self.labels = "path_denoised"
        self.dtype_ = config.torch_dtype
        self.scaler = FeatureScaler(n_features, self.dtype_, config.path_noise)

    @property
    def n_nodes(self) -> int:
        """The number of heads ``K``."""
        return len(self.node_keys)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Progress of every node: ``x (..., d)`` raw features -> ``(..., K)`` in [0, 1]."""
        if x.shape[-1] != self.n_features:
            raise DataError(
                f"expected feature vectors with {self.n_features} entries, got shape "
                f"{tuple(x.shape)}"
            )
        lead = x.shape[:-1]
        z = x.to(self.scaler.offset.device, self.dtype_).reshape(-1, self.n_features)
        if self.config.feature_scaling != "none":
            z = self.scaler(z)
        out = torch.sigmoid(self.logits(z))
        return out.reshape(*lead, out.shape[-1])

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        """Logits of every node for scaled features ``z (B, d)`` -> ``(B, K)``."""
        raise NotImplementedError

    def node_logits(self, z: torch.Tensor, i: int) -> torch.Tensor:
        """Logits ``(B,)`` of node ``i`` alone for scaled features ``z (B, d)``.

        Banks override this to skip the other nodes' work (e.g. to score each node on its own
        samples).
        """
        return self.logits(z)[:, i]

    def reset_state(self, n_streams: int) -> None:
        """Start ``n_streams`` fresh input streams (stateful banks); a no-op for the others."""

    def set_validation(self, validation: list[NodeData] | None) -> None:
        """Receive the fit's held-out data before :meth:`initialize` (default: not used).

        :func:`~cpmp.predictors.training.fit_predictor` passes the validation data it scores
        every epoch on, so that a bank can choose among models on them (``klr_sparse``
        chooses its sparsity level).

        Args:
            validation: every node's held-out data in node order (a node may have none), or
                ``None`` when the fit has none.
        """

    def initialize(self, data: list[NodeData], generator: torch.Generator) -> None:
        """Data-dependent set-up before training (support points, initial weights)."""

    def training_loss(
        self, data: list[NodeData], rows: list[torch.Tensor] | None = None
    ) -> torch.Tensor:
        """Sum over nodes of the mean soft-label BCE (eq. 5) plus regularisation.

        Args:
            data: every node's training data, in node order.
            rows: per node, the rows of its data in this mini-batch (``(b_i,)`` indices, at
                least one each); ``None``: all of them (full batch). Banks trained by Adam
                take mini-batches; the others only the full batch.

        Returns:
            The scalar loss.
        """
        raise NotImplementedError

    def solve_convex(self, data: list[NodeData], solver: SolverOptions) -> list[NewtonInfo]:
        """Set the trainable parameters to the minimiser of :meth:`training_loss`.

        By Newton's method (convex banks only).

        Args:
            data: every node's training data (on the bank's device).
            solver: the solver's tolerances.

        Returns:
            Each node's solver outcome.
        """
        raise NotImplementedError(f"predictor {self.kind!r} is not convex")

    def finalize(self, data: list[NodeData], solver: SolverOptions | None = None) -> None:
        """Post-training step (e.g. pruning, a convex re-fit by ``solver``); default none."""

    def summary(self) -> dict[str, JsonValue]:
        """Per-model facts worth reporting (e.g. support-point counts)."""
        return {"kind": self.kind, "n_nodes": self.n_nodes, "n_parameters": self.n_parameters()}

    def n_parameters(self) -> int:
        """The number of parameter entries (trainable or not)."""
        return sum(p.numel() for p in self.parameters())

    def shape_spec(self) -> dict[str, int]:
        """Sizes needed to re-create the module before ``load_state_dict``."""
        return {}

    def spec(self) -> dict[str, JsonValue]:
        """Everything needed to rebuild this module (without its weights)."""
        return {
            "kind": self.kind,
            "config": dataclasses.asdict(self.config),
            "node_keys": [list(k) for k in self.node_keys],
            "n_features": self.n_features,
            "shapes": self.shape_spec(),
        }


def soft_bce(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean soft-label binary cross-entropy of eq. 5 (numerically stable, from logits)."""
    return F.binary_cross_entropy_with_logits(logits, target, reduction="mean")
