"""Running one episode of a policy on an env: the loop the evaluation CLI and the demo generator share."""

from __future__ import annotations

from typing import Callable, Optional

from mani_skill.utils import gym_utils

from mani_skill_space.metrics import EpisodeResult


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
    total, first_success, steps, success = 0.0, None, 0, False
    for steps in range(1, episode_steps(env) + 1):
        obs, reward, _, truncated, info = env.step(policy.act(obs))
        total += float(reward)
        success = bool(info["success"])
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
        failure=getattr(policy, "failure", None) or "",
    )
