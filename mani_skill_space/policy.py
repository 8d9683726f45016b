"""The policy protocol every runner (evaluation CLI, demo generator, baselines) speaks. A leaf module: it imports
nothing of ours, so policies, oracles and learners can all build on it without import cycles.

A policy is an object with ``act(obs) -> action``. It may also define ``control_mode`` (the env is made with it;
None keeps the env's default), ``obs_mode`` (likewise, e.g. a checkpoint trained on RGB-D) and
``reset(env, seed)`` (called after every ``env.reset(seed=seed)``; ``env`` is the gym env, so privileged
policies such as the oracles can read ``env.unwrapped``).
"""

from __future__ import annotations

from typing import Optional

import numpy as np


class Policy:
    control_mode: Optional[str] = None
    obs_mode: Optional[str] = None

    def reset(self, env, seed: int) -> None:
        """Called after each ``env.reset(seed=seed)``."""

    def act(self, obs) -> np.ndarray:
        raise NotImplementedError


class WrapsOracle(Policy):
    """A policy that acts through ``self.oracle``, a scripted policy, and reports its ``done`` and ``failure`` (the
    runners read them: a demonstration ends when the oracle is done, and its failure is recorded)."""

    oracle: Policy

    @property
    def done(self) -> bool:
        return self.oracle.done

    @property
    def failure(self) -> Optional[str]:
        return self.oracle.failure

    @property
    def phase(self) -> str:
        return self.oracle.phase
