"""Reward maths shared by every task (sim-free, batched torch).

A task's reward is a table of named terms. Shaped terms turn a distance d into ``w * (1 - tanh(d / sigma))``;
the other terms take a value already in [0, 1] (an indicator or a normalised penalty) times ``w``. Because
every term is bounded, the dense reward is bounded by ``[min_reward, max_reward]`` and the normalised dense
reward is the affine map of that interval onto [0, 1]. Success overrides the sum with ``max_reward``, as
ManiSkill's tasks do.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Optional

import torch


def tolerance(distance: torch.Tensor, sigma: float) -> torch.Tensor:
    """1 at distance 0, decaying smoothly to 0; ``sigma`` sets the scale (the reference's shaping)."""
    return 1.0 - torch.tanh(distance / sigma)


def band_distance(value: torch.Tensor, low: float, high: float) -> torch.Tensor:
    """Distance of ``value`` from the interval [low, high] (0 inside it)."""
    return torch.clamp(low - value, min=0.0) + torch.clamp(value - high, min=0.0)


def action_rate(action: torch.Tensor, previous_action: torch.Tensor, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """Mean squared change of the action between steps, normalised by the action range to [0, 1]."""
    change = (action - previous_action) / (high - low)
    return (change**2).mean(dim=-1)


@dataclass(frozen=True)
class RewardTerm:
    name: str
    weight: float
    sigma: Optional[float] = None
    """Shaping scale for distance terms; None for terms whose input is already in [0, 1]."""

    def __call__(self, value: torch.Tensor) -> torch.Tensor:
        value = value.float()
        return self.weight * (tolerance(value, self.sigma) if self.sigma is not None else value)


@dataclass(frozen=True)
class RewardTable:
    terms: tuple[RewardTerm, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(t.name for t in self.terms)

    @property
    def max_reward(self) -> float:
        return float(sum(t.weight for t in self.terms if t.weight > 0))

    @property
    def min_reward(self) -> float:
        return float(sum(t.weight for t in self.terms if t.weight < 0))

    def weighted(self, inputs: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Each term's contribution; ``inputs`` must name exactly this table's terms."""
        if set(inputs) != set(self.names):
            raise KeyError(f"reward inputs {sorted(inputs)} do not match the terms {sorted(self.names)}")
        return {t.name: t(inputs[t.name]) for t in self.terms}

    def dense(self, weighted: Mapping[str, torch.Tensor], success: torch.Tensor) -> torch.Tensor:
        total = torch.stack([weighted[name] for name in self.names]).sum(dim=0)
        return torch.where(success, torch.full_like(total, self.max_reward), total)

    def normalize(self, dense: torch.Tensor) -> torch.Tensor:
        return (dense - self.min_reward) / (self.max_reward - self.min_reward)

