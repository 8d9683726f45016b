"""Procgen-style levels: which procedural content a reconfiguration builds (sim-free).

A level is an integer that seeds everything a scene's reconfiguration generates (object assets, terrain, sun
direction). ``num_levels`` and ``start_level`` have Procgen's meaning: each reconfiguration draws its level as
``start_level + k`` with ``k`` uniform in ``[0, num_levels)`` from the episode's RNG; ``num_levels = 0`` leaves
the levels unbounded, and then an episode's level is ``start_level + its episode seed`` (so with the defaults an
episode seed builds the scene it always built, and level ``L`` looks the same whichever way it was drawn).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np

from mani_skill_space.kwarg_checks import KwargError

MAX_START_LEVEL = 2**31 - 1
LEVEL_LIMIT = 2**32
"""Levels seed numpy's RandomState, which takes seeds below 2**32; episode seeds are below 2**31."""


@dataclass(frozen=True)
class LevelRange:
    num_levels: int = 0
    start_level: int = 0

    def draw(self, episode_seeds: np.ndarray, episode_rng) -> np.ndarray:
        """The level (int64) of each env: ``start_level + k``, ``k`` drawn from ``episode_rng`` (ManiSkill's
        batched episode RNG, one draw per env) below ``num_levels``, or the episode seed when unbounded."""
        if self.num_levels == 0:
            return self.start_level + np.asarray(episode_seeds, dtype=np.int64)
        return self.start_level + np.asarray(episode_rng.randint(0, self.num_levels), dtype=np.int64)

    def level_of(self, episode_seed: int) -> int:
        """The level a single env builds when reset (with a rebuild) with ``episode_seed``: what ``draw`` gives
        with ManiSkill's episode RNG, a ``RandomState`` seeded with the episode seed."""
        if self.num_levels == 0:
            return self.start_level + int(episode_seed)
        return self.start_level + int(np.random.RandomState(int(episode_seed)).randint(0, self.num_levels))

    @property
    def bounded(self) -> bool:
        return self.num_levels > 0

    def contains(self, level: int) -> bool:
        return self.start_level <= level and (not self.bounded or level < self.start_level + self.num_levels)


def check_level_kwargs(kwargs: dict[str, Any]) -> dict[str, int]:
    """``num_levels`` and ``start_level`` from ``kwargs`` (0 when missing), checked: ints, ``start_level`` at
    most 2**31 - 1 and ``start_level + num_levels`` at most 2**32."""
    checked = {}
    for name, meaning in (
        ("num_levels", "how many levels reconfigurations draw from; 0: unbounded, every episode seed its own level"),
        ("start_level", "the first level"),
    ):
        value = kwargs.get(name, 0)
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
            raise KwargError(name, f"{name} must be an integer >= 0 ({meaning}), got {value!r}")
        checked[name] = int(value)
    if checked["start_level"] > MAX_START_LEVEL:
        raise KwargError("start_level", f"start_level must be an integer >= 0 and <= {MAX_START_LEVEL}, got {checked['start_level']}")
    if checked["start_level"] + checked["num_levels"] > LEVEL_LIMIT:
        raise KwargError("num_levels", f"start_level + num_levels must be <= {LEVEL_LIMIT} (levels seed numpy's RandomState), got {checked['start_level'] + checked['num_levels']}")
    return checked
