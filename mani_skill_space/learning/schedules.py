"""Learning-rate schedules of the imitation baselines, over a budget of iterations or minutes."""

from __future__ import annotations

import math
from typing import Literal, get_args

import torch

LrSchedule = Literal["constant", "cosine"]
"""The ``--lr-schedule`` choices of the imitation baselines."""
LR_SCHEDULES: tuple[str, ...] = get_args(LrSchedule)


def set_learning_rate(optimiser: torch.optim.Optimizer, args, iteration: int, minutes: float) -> None:
    """Set the learning rate for ``iteration`` after ``minutes`` of training, given ``args`` (a baseline's:
    ``lr``, ``lr_schedule``, ``max_iterations``, ``minutes``). ``cosine`` decays ``args.lr`` to zero over the
    budget that ends first, as ManiSkill's diffusion policy baseline does over its iterations."""
    if args.lr_schedule not in LR_SCHEDULES:
        raise ValueError(f"unknown lr_schedule {args.lr_schedule!r}; valid choices: {', '.join(LR_SCHEDULES)}")
    if args.lr_schedule == "constant":
        return
    progress = min(1.0, max(iteration / args.max_iterations, minutes / args.minutes))
    for group in optimiser.param_groups:
        group["lr"] = args.lr * 0.5 * (1.0 + math.cos(math.pi * progress))
