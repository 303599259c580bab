"""Test doubles of progress predictors shared by the sequencer tests."""

from __future__ import annotations

from typing import ClassVar

import torch

from cpmp.predictors import ProgressPredictor


class FirstColumnsAreProgress(ProgressPredictor):
    """Test double: node k's progress is feature k; the features after the nodes' are state."""

    kind: ClassVar[str] = "first_columns_are_progress"

    def logits(self, z: torch.Tensor) -> torch.Tensor:
        return torch.logit(z[:, : self.n_nodes].clamp(1e-9, 1 - 1e-9))
