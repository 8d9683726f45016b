"""Vectorised training envs: GPU-batched ManiSkill envs on CUDA, worker processes on the CPU."""

from __future__ import annotations

from typing import Optional

import numpy as np
import torch

from mani_skill_space.learning.observations import STATE_OBS_MODES, encode_observation


class VectorEnv:
    """N envs stepped together, torch in and out, auto-resetting in the same step (the final observation of a
    finished episode is kept for bootstrapping). On CUDA: one GPU-batched ManiSkill env; on the CPU:
    ``gymnasium.vector.AsyncVectorEnv`` of single envs in worker processes, as ManiSkill runs CPU envs."""

    def __init__(
        self, env_id: str, num_envs: int, env_kwargs: dict, obs_mode: str, control_mode: str, device: torch.device, gpu: Optional[bool] = None, reward_mode: str = "normalized_dense"
    ):
        import gymnasium as gym

        self.obs_mode, self.device, self.num_envs = obs_mode, device, num_envs
        kwargs = dict(env_kwargs, obs_mode=obs_mode, control_mode=control_mode, reward_mode=reward_mode)
        if obs_mode in STATE_OBS_MODES:
            kwargs.setdefault("render_backend", "none")
        self.gpu = torch.cuda.is_available() if gpu is None else gpu
        if self.gpu:
            from mani_skill.vector.wrappers.gymnasium import ManiSkillVectorEnv

            self.env = ManiSkillVectorEnv(gym.make(env_id, num_envs=num_envs, sim_backend="physx_cuda", **kwargs), num_envs, ignore_terminations=False, record_metrics=False)
        else:
            self.env = gym.vector.AsyncVectorEnv(
                [CPUEnvFactory(env_id, kwargs) for _ in range(num_envs)], context="spawn", autoreset_mode=gym.vector.AutoresetMode.SAME_STEP
            )
        self.single_action_space = self.env.single_action_space

    def reset(self, seed: int) -> dict[str, torch.Tensor]:
        obs, _ = self.env.reset(seed=seed if self.gpu else [seed + i for i in range(self.num_envs)])
        return self._encode(obs)

    def step(self, action: torch.Tensor):
        """obs, reward, terminated, truncated, final_obs (None or the encoded final observations, valid where
        done), success (per env, this step)."""
        action = action if self.gpu else action.cpu().numpy()
        obs, reward, terminated, truncated, info = self.env.step(action)
        as_tensor = lambda x: torch.as_tensor(np.asarray(x) if not isinstance(x, torch.Tensor) else x, device=self.device)  # noqa: E731
        done = as_tensor(terminated).bool() | as_tensor(truncated).bool()
        final_obs = None
        if done.any():
            final = info["final_observation"] if self.gpu else info["final_obs"]
            if not self.gpu:  # per-env entries (None where not done): stack, filling with the new obs
                final = _stack_final(final, obs, np.asarray(done.cpu()))
            final_obs = self._encode(final)
        success = info["final_info"]["success"] if self.gpu and "final_info" in info and done.any() else info.get("success")
        if not self.gpu and done.any():
            final_info = info["final_info"]
            success = np.where(np.asarray(done.cpu()), final_info.get("success", np.zeros(self.num_envs, bool)), info["success"])
        return self._encode(obs), as_tensor(reward).float(), as_tensor(terminated).bool(), as_tensor(truncated).bool(), final_obs, as_tensor(success).bool()

    def _encode(self, obs) -> dict[str, torch.Tensor]:
        return encode_observation(obs, self.obs_mode, self.device)

    def close(self) -> None:
        self.env.close()


class CPUEnvFactory:
    """Picklable constructor of one CPU env for a spawned worker."""

    def __init__(self, env_id: str, kwargs: dict):
        self.env_id, self.kwargs = env_id, kwargs

    def __call__(self):
        import gymnasium as gym
        from mani_skill.utils.wrappers import CPUGymWrapper

        import mani_skill_space  # noqa: F401  (registers the envs in the worker)

        return CPUGymWrapper(gym.make(self.env_id, **self.kwargs), ignore_terminations=False)


def _stack_final(final, obs, done: np.ndarray):
    """AsyncVectorEnv's final observations (an object array, None where an env is not done) as one batch,
    with the current observations of the envs that did not finish."""
    rows = [final[i] if done[i] and final[i] is not None else _row(obs, i) for i in range(len(done))]
    return _stack(rows)


def _row(batch, i: int):
    return {k: _row(v, i) for k, v in batch.items()} if isinstance(batch, dict) else batch[i]


def _stack(rows: list):
    return {k: _stack([r[k] for r in rows]) for k in rows[0]} if isinstance(rows[0], dict) else np.stack(rows)

