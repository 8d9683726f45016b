"""The built-in policies and ``load_policy`` (see ``mani_skill_space.policy`` for the protocol).

``load_policy(spec)`` turns a CLI spec into a policy: ``random``, ``zero``, ``oracle`` (acting in
``pd_joint_pos``), ``oracle-ee`` (the same oracle acting in ``pd_ee_delta_pose``), ``checkpoint:PATH`` (a
baseline trained by ``baselines/*.py``, see ``mani_skill_space.learning``) or ``module:callable``, where
``callable`` is a zero-argument factory returning such an object.
"""

from __future__ import annotations

import importlib
from typing import Any, Callable

import numpy as np

from mani_skill_space.policy import Policy, WrapsOracle

BUILTIN_POLICIES = ("random", "zero", "oracle", "oracle-ee")


class RandomPolicy(Policy):
    """Uniform actions from the env's action space, seeded per episode (same seed, same actions)."""

    def reset(self, env, seed: int) -> None:
        self.space = env.action_space
        self.space.seed(seed)

    def act(self, obs) -> np.ndarray:
        return self.space.sample()


class ZeroPolicy(Policy):
    """All-zero actions (with ``pd_ee_delta_pose``: hold the pose, gripper half open)."""

    def reset(self, env, seed: int) -> None:
        self.action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)

    def act(self, obs) -> np.ndarray:
        return self.action


class OraclePolicy(WrapsOracle):
    """Dispatches to the motion-planning oracle of whichever env it is reset on, acting in ``control_mode``
    (``pd_joint_pos``, or ``pd_ee_delta_pose``: see ``mani_skill_space.oracles.end_effector``)."""

    def __init__(self, control_mode: str = "pd_joint_pos"):
        self.control_mode = control_mode

    def reset(self, env, seed: int) -> None:
        from mani_skill_space.oracles import oracle_for

        env_id = env.unwrapped.spec.id if env.unwrapped.spec else type(env.unwrapped).__name__
        self.oracle = oracle_for(env_id, self.control_mode)
        self.oracle.reset(env, seed)

    def act(self, obs) -> np.ndarray:
        return self.oracle.act(obs)


def load_policy(spec: str) -> Policy:
    builtins: dict[str, Callable[[], Any]] = {
        "random": RandomPolicy,
        "zero": ZeroPolicy,
        "oracle": OraclePolicy,
        "oracle-ee": lambda: OraclePolicy("pd_ee_delta_pose"),
    }
    if spec in builtins:
        return builtins[spec]()
    if spec.startswith("checkpoint:"):
        from mani_skill_space.learning import CheckpointPolicy

        return CheckpointPolicy(spec.partition(":")[2])
    if ":" not in spec:
        raise ValueError(f"Unknown policy {spec!r}; valid choices: {', '.join(BUILTIN_POLICIES)}, checkpoint:PATH or module:callable")
    module_name, _, attribute = spec.partition(":")
    factory = getattr(importlib.import_module(module_name), attribute)
    policy = factory()
    if not callable(getattr(policy, "act", None)):
        raise TypeError(f"{spec}() returned {policy!r}, which has no act(obs) method")
    return policy
