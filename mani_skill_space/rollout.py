"""Running a policy on an env: the episode loop and the evaluation protocol that the evaluation CLI, the demo
generator and the baselines' training-time evaluations share."""

from __future__ import annotations

from typing import Callable, Optional, Sequence

from mani_skill.utils import gym_utils

from mani_skill_space.metrics import EpisodeResult

STATE_OBS_MODES = ("state", "state_dict", "none")
"""Observation modes that need no rendering: their envs are made with ``render_backend="none"``."""


def evaluation_env_kwargs(kwargs: dict, policy, render: bool = False) -> dict:
    """The env kwargs an evaluation makes its env with: the task's ``kwargs``, the policy's control and obs mode
    where it names them, and no renderer unless frames are wanted or the observations need one."""
    kwargs = dict(kwargs)
    for key in ("control_mode", "obs_mode"):
        if getattr(policy, key, None) is not None:
            kwargs[key] = getattr(policy, key)
    if render:
        kwargs["render_mode"] = "rgb_array"
    elif kwargs.get("obs_mode", "state") in STATE_OBS_MODES:
        kwargs.setdefault("render_backend", "none")
    return kwargs


def episode_steps(env) -> int:
    return gym_utils.find_max_episode_steps_value(env)


def run_episode(
    env,
    policy,
    seed: int,
    stop_when_done: bool = False,
    on_step: Optional[Callable[[], None]] = None,
) -> EpisodeResult:
    """Reset ``env`` with ``seed`` (rebuilding the scene, so the outcome depends on the seed alone) and step
    ``policy`` until the time limit. Terminations are ignored, as in ManiSkill's evaluations, so that
    ``success_at_end`` is meaningful. ``stop_when_done`` ends the episode once a scripted policy (an oracle)
    has finished, as demonstrations do. ``on_step`` runs after the reset and after every step (e.g. to render).
    """
    obs, _ = env.reset(seed=seed, options=dict(reconfigure=True))
    if hasattr(policy, "reset"):
        policy.reset(env, seed)
    if on_step is not None:
        on_step()
    total, first_success, steps, success, stage = 0.0, None, 0, False, None
    for steps in range(1, episode_steps(env) + 1):
        obs, reward, _, truncated, info = env.step(policy.act(obs))
        total += float(reward)
        success = bool(info["success"])
        if "stage" in info:
            reached = int(info["stage"])
            stage = reached if stage is None else max(stage, reached)
        if success and first_success is None:
            first_success = steps
        if on_step is not None:
            on_step()
        if bool(truncated) or (stop_when_done and getattr(policy, "done", False)):
            break
    return EpisodeResult(
        seed=seed,
        success_once=first_success is not None,
        success_at_end=success,
        episode_return=total,
        episode_len=first_success or steps,
        failure=failure_of(policy, success),
        stage=stage,
    )


def failure_of(policy, success_at_end: bool) -> str:
    """``EpisodeResult.failure`` of an episode that ``policy`` ran to its end."""
    if getattr(policy, "failure", None):
        return policy.failure
    if success_at_end or getattr(policy, "phase", None) is None:
        return ""
    if getattr(policy, "done", False):
        return f"the plan ended without success after {policy.phase}"
    return f"time ran out while {policy.phase}"


def evaluate_policy(policy, env_id: str, env_kwargs: dict, seeds: Sequence[int]) -> dict[str, float]:
    """success_once, success_at_end and mean return of ``policy`` over ``seeds``, by the evaluation CLI's protocol
    (its env kwargs, a fresh scene per seed, episodes to the time limit)."""
    import gymnasium as gym

    env = gym.make(env_id, **evaluation_env_kwargs(env_kwargs, policy))
    try:
        results = [run_episode(env, policy, seed) for seed in seeds]
    finally:
        env.close()
    return dict(
        success_once=sum(r.success_once for r in results) / len(results),
        success_at_end=sum(r.success_at_end for r in results) / len(results),
        episode_return=sum(r.episode_return for r in results) / len(results),
    )
