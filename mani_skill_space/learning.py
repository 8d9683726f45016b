"""What the learning baselines (``baselines/``) share with the evaluation CLI: observation encoding, the
networks, vectorised training envs, learning-curve logs and checkpoints.

A checkpoint (``torch.save`` of a dict) names its algorithm, env id, env kwargs, obs and control mode and the
network (class name, constructor kwargs, weights), so ``python -m mani_skill_space.eval --policy
checkpoint:PATH`` rebuilds the policy and scores it by the same protocol as every other policy.
"""

from __future__ import annotations

import csv
import shutil
from collections import deque
from pathlib import Path
from typing import Any, Optional, Sequence

import numpy as np
import torch
import torch.nn as nn

from mani_skill_space.policies import Policy

IMAGE_OBS_MODES = ("rgbd",)
STATE_OBS_MODES = ("state",)


# ---------------------------------------------------------------------- observations
def encode_observation(obs: Any, obs_mode: str, device: torch.device) -> dict[str, torch.Tensor]:
    """A batched env observation as the networks take it: ``{"state": (n, d)}`` in state mode; in rgbd mode
    also ``"rgb"`` (n, H, W, 3 x cameras, uint8) and ``"depth"`` (n, H, W, cameras), as ManiSkill's
    ``FlattenRGBDObservationWrapper`` lays them out."""
    from mani_skill.utils import common

    if obs_mode in STATE_OBS_MODES:
        return {"state": torch.as_tensor(obs, device=device).float()}
    if obs_mode not in IMAGE_OBS_MODES:
        raise ValueError(f"Unsupported obs_mode {obs_mode!r} for the baselines; valid choices: {', '.join(STATE_OBS_MODES + IMAGE_OBS_MODES)}")
    obs = common.to_tensor(obs, device=device)
    cameras = obs["sensor_data"].values()
    state = common.flatten_state_dict({k: v for k, v in obs.items() if k not in ("sensor_data", "sensor_param")}, use_torch=True, device=device)
    return {
        "state": state.float(),
        "rgb": torch.cat([c["rgb"] for c in cameras], dim=-1),
        "depth": torch.cat([c["depth"] for c in cameras], dim=-1),
    }


# ---------------------------------------------------------------------- networks
def mlp(sizes: Sequence[int], activation=nn.ReLU, output_activation=None) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(activation())
        elif output_activation is not None:
            layers.append(output_activation())
    return nn.Sequential(*layers)


class ObservationEncoder(nn.Module):
    """State as is; in rgbd mode, RGB and depth (metres, clipped) through a small CNN (ManiSkill's PPO-RGB
    encoder: NatureCNN-like) concatenated with the state."""

    def __init__(self, state_dim: int, image_channels: int = 0, image_size: int = 64, features: int = 256):
        super().__init__()
        self.state_dim, self.image_channels = state_dim, image_channels
        self.out_dim = state_dim
        if image_channels:
            self.cnn = nn.Sequential(
                nn.Conv2d(image_channels, 32, 8, stride=4),
                nn.ReLU(),
                nn.Conv2d(32, 64, 4, stride=2),
                nn.ReLU(),
                nn.Conv2d(64, 64, 3, stride=1),
                nn.ReLU(),
                nn.Flatten(),
            )
            with torch.no_grad():
                flat = self.cnn(torch.zeros(1, image_channels, image_size, image_size)).shape[1]
            self.image_head = nn.Sequential(nn.Linear(flat, features), nn.ReLU())
            self.out_dim = state_dim + features

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        if not self.image_channels:
            return obs["state"]
        depth = torch.clamp(obs["depth"].float() / 1000.0, 0.0, 4.0)  # ManiSkill depth is in millimetres
        image = torch.cat([obs["rgb"].float() / 255.0, depth], dim=-1).permute(0, 3, 1, 2)
        return torch.cat([obs["state"], self.image_head(self.cnn(image))], dim=-1)


class GaussianActorCritic(nn.Module):
    """PPO's agent (ManiSkill's baseline): a tanh MLP actor with a state-independent log std, and a critic."""

    def __init__(self, state_dim: int, action_dim: int, image_channels: int = 0, hidden: int = 256):
        super().__init__()
        self.encoder = ObservationEncoder(state_dim, image_channels)
        features = self.encoder.out_dim
        self.critic = nn.Sequential(mlp([features, hidden, hidden], nn.Tanh, nn.Tanh), nn.Linear(hidden, 1))
        self.actor_mean = nn.Sequential(mlp([features, hidden, hidden], nn.Tanh, nn.Tanh), nn.Linear(hidden, action_dim))
        nn.init.orthogonal_(self.actor_mean[-1].weight, 0.01)
        self.actor_logstd = nn.Parameter(torch.full((1, action_dim), -0.5))

    def value(self, obs) -> torch.Tensor:
        return self.critic(self.encoder(obs)).squeeze(-1)

    def distribution(self, obs) -> tuple[torch.distributions.Normal, torch.Tensor]:
        features = self.encoder(obs)
        mean = self.actor_mean(features)
        return torch.distributions.Normal(mean, self.actor_logstd.expand_as(mean).exp()), self.critic(features).squeeze(-1)

    def act(self, obs) -> torch.Tensor:
        return self.actor_mean(self.encoder(obs))


class SquashedGaussianActor(nn.Module):
    """SAC's actor: a tanh-squashed Gaussian scaled to the action bounds."""

    LOG_STD_RANGE = (-5.0, 2.0)

    def __init__(self, state_dim: int, action_dim: int, action_low: Sequence[float], action_high: Sequence[float], hidden: int = 256):
        super().__init__()
        self.body = mlp([state_dim, hidden, hidden], output_activation=nn.ReLU)
        self.mean = nn.Linear(hidden, action_dim)
        self.log_std = nn.Linear(hidden, action_dim)
        low, high = torch.as_tensor(action_low, dtype=torch.float32), torch.as_tensor(action_high, dtype=torch.float32)
        self.register_buffer("scale", (high - low) / 2)
        self.register_buffer("bias", (high + low) / 2)

    def sample(self, obs) -> tuple[torch.Tensor, torch.Tensor]:
        hidden = self.body(obs["state"])
        mean, log_std = self.mean(hidden), torch.clamp(self.log_std(hidden), *self.LOG_STD_RANGE)
        normal = torch.distributions.Normal(mean, log_std.exp())
        raw = normal.rsample()
        squashed = torch.tanh(raw)
        log_prob = normal.log_prob(raw) - torch.log(self.scale * (1 - squashed.pow(2)) + 1e-6)
        return squashed * self.scale + self.bias, log_prob.sum(-1)

    def act(self, obs) -> torch.Tensor:
        return torch.tanh(self.mean(self.body(obs["state"]))) * self.scale + self.bias


OBS_CLIP = 5.0
"""Normalised observations are clipped to +-5 standard deviations: contact forces (the wrist wrench) have heavy
tails, and an unseen spike would otherwise swamp the network's input."""


class BehaviourCloningPolicy(nn.Module):
    """An MLP from (normalised, clipped) state to action."""

    def __init__(self, state_dim: int, action_dim: int, hidden: int = 512, depth: int = 3):
        super().__init__()
        self.net = mlp([state_dim, *([hidden] * depth), action_dim])
        self.register_buffer("obs_mean", torch.zeros(state_dim))
        self.register_buffer("obs_std", torch.ones(state_dim))

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        return self.net(torch.clamp((state - self.obs_mean) / self.obs_std, -OBS_CLIP, OBS_CLIP))

    def act(self, obs) -> torch.Tensor:
        return self(obs["state"])


class DiffusionNoisePredictor(nn.Module):
    """The diffusion policy's denoiser: predicts the noise in an action chunk, given the observation history
    and the diffusion step (an MLP version of Chi et al.'s conditional network)."""

    def __init__(self, state_dim: int, action_dim: int, obs_horizon: int, action_horizon: int, hidden: int = 512, step_features: int = 64):
        super().__init__()
        self.state_dim, self.action_dim, self.obs_horizon, self.action_horizon = state_dim, action_dim, obs_horizon, action_horizon
        self.step_features = step_features
        self.net = mlp([action_dim * action_horizon + state_dim * obs_horizon + step_features, hidden, hidden, hidden, action_dim * action_horizon], nn.Mish)
        self.register_buffer("obs_mean", torch.zeros(state_dim))
        self.register_buffer("obs_std", torch.ones(state_dim))

    def forward(self, noisy_actions: torch.Tensor, step: torch.Tensor, obs_history: torch.Tensor) -> torch.Tensor:
        n = noisy_actions.shape[0]
        half = self.step_features // 2
        frequencies = torch.exp(-np.log(10000.0) * torch.arange(half, device=step.device) / half)
        angles = step.float().reshape(-1, 1) * frequencies[None]
        step_embedding = torch.cat([angles.sin(), angles.cos()], dim=-1).expand(n, -1)
        conditioning = torch.clamp((obs_history - self.obs_mean) / self.obs_std, -OBS_CLIP, OBS_CLIP).reshape(n, -1)
        out = self.net(torch.cat([noisy_actions.reshape(n, -1), conditioning, step_embedding], dim=-1))
        return out.reshape(n, self.action_horizon, self.action_dim)


MODELS = {cls.__name__: cls for cls in (GaussianActorCritic, SquashedGaussianActor, BehaviourCloningPolicy, DiffusionNoisePredictor)}


# ---------------------------------------------------------------------- checkpoints
def save_checkpoint(path: Path, algorithm: str, model: nn.Module, model_kwargs: dict, env_id: str, env_kwargs: dict, obs_mode: str, control_mode: str, **extra) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(
        dict(
            algorithm=algorithm,
            model_class=type(model).__name__,
            model_kwargs=model_kwargs,
            state_dict={k: v.detach().cpu() for k, v in model.state_dict().items()},
            env_id=env_id,
            env_kwargs=env_kwargs,
            obs_mode=obs_mode,
            control_mode=control_mode,
            **extra,
        ),
        path,
    )
    return path


def load_model(checkpoint: dict, device: str = "cpu") -> nn.Module:
    if checkpoint["model_class"] not in MODELS:
        raise ValueError(f"Unknown model class {checkpoint['model_class']!r} in checkpoint; valid choices: {', '.join(MODELS)}")
    model = MODELS[checkpoint["model_class"]](**checkpoint["model_kwargs"])
    model.load_state_dict(checkpoint["state_dict"])
    return model.to(device).eval()


class CheckpointPolicy(Policy):
    """A trained baseline, deterministic (the mean action, or the diffusion policy's denoised chunk)."""

    def __init__(self, path: str, device: str = "cpu"):
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"No checkpoint at {self.path}")
        self.checkpoint = torch.load(self.path, map_location=device, weights_only=False)
        self.device = torch.device(device)
        self.model = load_model(self.checkpoint, device)
        self.control_mode = self.checkpoint["control_mode"]
        self.obs_mode = self.checkpoint["obs_mode"]
        self.env_id = self.checkpoint["env_id"]
        self.diffusion = self.checkpoint.get("diffusion")
        if self.diffusion is not None:
            from diffusers.schedulers.scheduling_ddpm import DDPMScheduler

            self.scheduler = DDPMScheduler(**self.diffusion["scheduler"])

    def reset(self, env, seed: int) -> None:
        running = env.unwrapped.spec.id if env.unwrapped.spec else None
        if running is not None and running != self.env_id:
            raise ValueError(f"{self.path} was trained on {self.env_id}, not {running}")
        self.history: deque = deque(maxlen=self.diffusion["obs_horizon"] if self.diffusion else 1)
        self.queue: deque = deque()

    @torch.no_grad()
    def act(self, obs) -> torch.Tensor:
        encoded = encode_observation(obs, self.obs_mode, self.device)
        if self.diffusion is None:
            return self.model.act(encoded)
        state = encoded["state"]
        while len(self.history) < self.history.maxlen:
            self.history.append(state)
        self.history.append(state)
        if not self.queue:
            chunk = denoise(self.model, self.scheduler, torch.stack(list(self.history), dim=1), self.diffusion["inference_steps"])
            self.queue.extend(chunk[:, i] for i in range(self.diffusion["execute_horizon"]))
        return self.queue.popleft()


def denoise(model: DiffusionNoisePredictor, scheduler, obs_history: torch.Tensor, inference_steps: int, generator: Optional[torch.Generator] = None) -> torch.Tensor:
    """Sample an action chunk (n, action_horizon, action_dim) by running the reverse diffusion."""
    actions = torch.randn((obs_history.shape[0], model.action_horizon, model.action_dim), generator=generator, device=obs_history.device)
    scheduler.set_timesteps(inference_steps)
    for step in scheduler.timesteps:
        noise = model(actions, step.to(obs_history.device), obs_history)
        actions = scheduler.step(noise, step, actions).prev_sample
    return actions.clamp(-1.0, 1.0)


# ---------------------------------------------------------------------- training envs
class VectorEnv:
    """N envs stepped together, torch in and out, auto-resetting in the same step (the final observation of a
    finished episode is kept for bootstrapping). On CUDA: one GPU-batched ManiSkill env; on the CPU:
    ``gymnasium.vector.AsyncVectorEnv`` of single envs in worker processes, as ManiSkill runs CPU envs."""

    def __init__(self, env_id: str, num_envs: int, env_kwargs: dict, obs_mode: str, control_mode: str, device: torch.device, gpu: Optional[bool] = None):
        import gymnasium as gym

        self.obs_mode, self.device, self.num_envs = obs_mode, device, num_envs
        kwargs = dict(env_kwargs, obs_mode=obs_mode, control_mode=control_mode, reward_mode="normalized_dense")
        if obs_mode in STATE_OBS_MODES:
            kwargs.setdefault("render_backend", "none")
        self.gpu = torch.cuda.is_available() if gpu is None else gpu
        if self.gpu:
            from mani_skill.vector.wrappers.gymnasium import ManiSkillVectorEnv

            self.env = ManiSkillVectorEnv(gym.make(env_id, num_envs=num_envs, sim_backend="physx_cuda", **kwargs), num_envs, ignore_terminations=False, record_metrics=False)
        else:
            self.env = gym.vector.AsyncVectorEnv(
                [_SingleEnvFactory(env_id, kwargs) for _ in range(num_envs)], context="spawn", autoreset_mode=gym.vector.AutoresetMode.SAME_STEP
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


class _SingleEnvFactory:
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


# ---------------------------------------------------------------------- learning curves
class LearningCurve:
    """Rows of metrics appended to ``curve.csv`` as training goes, plotted to ``curve.png`` on ``plot()``."""

    def __init__(self, run_dir: Path, fields: Sequence[str]):
        self.path = Path(run_dir) / "curve.csv"
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.fields = list(fields)
        with self.path.open("w", newline="") as f:
            csv.writer(f).writerow(self.fields)

    def log(self, **row) -> None:
        with self.path.open("a", newline="") as f:
            csv.writer(f).writerow([row.get(k, "") for k in self.fields])

    def plot(self, x: str, ys: Sequence[str], title: str) -> Path:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        rows = list(csv.DictReader(self.path.open()))
        figure, axes = plt.subplots(len(ys), 1, figsize=(6, 2.4 * len(ys)), sharex=True, squeeze=False)
        for axis, y in zip(axes[:, 0], ys):
            points = [(float(r[x]), float(r[y])) for r in rows if r.get(y) not in ("", None)]
            if points:
                axis.plot(*zip(*points), marker=".")
            axis.set_ylabel(y)
            axis.grid(alpha=0.3)
        axes[-1, 0].set_xlabel(x)
        axes[0, 0].set_title(title)
        figure.tight_layout()
        out = self.path.with_suffix(".png")
        figure.savefig(out, dpi=100)
        plt.close(figure)
        return out


# ---------------------------------------------------------------------- demonstrations and evaluation
def load_demonstrations(path: Path, success_only: bool = True, limit: Optional[int] = None) -> tuple[list[dict[str, np.ndarray]], dict]:
    """Episodes of a ManiSkill trajectory file (``.h5`` + ``.json``, state observations): a list of
    ``{"obs": (T + 1, d), "actions": (T, a)}`` and the file's env info (env id, env kwargs)."""
    import json

    import h5py

    path = Path(path)
    meta = json.loads(path.with_suffix(".json").read_text())
    episodes = []
    with h5py.File(path, "r") as data:
        for episode in meta["episodes"]:
            if success_only and not episode.get("success", False):
                continue
            trajectory = data[f"traj_{episode['episode_id']}"]
            obs = trajectory["obs"]
            if not isinstance(obs, h5py.Dataset):
                raise ValueError(f"{path} has {sorted(obs.keys())} observations; convert it with obs mode 'state' (-o state)")
            episodes.append({"obs": np.asarray(obs, dtype=np.float32), "actions": np.asarray(trajectory["actions"], dtype=np.float32)})
            if limit is not None and len(episodes) >= limit:
                break
    if not episodes:
        raise ValueError(f"{path} holds no {'successful ' if success_only else ''}episodes")
    return episodes, meta["env_info"]


RECORDING_KWARGS = ("render_mode", "sim_backend", "reward_mode", "render_backend", "num_envs")
"""Env kwargs a trajectory file records that belong to how it was recorded, not to the task."""


def task_of_demonstrations(env_info: dict) -> tuple[str, dict, str, str]:
    """Env id, task kwargs (domain, asset source, ...), obs mode and control mode of a trajectory file's env info."""
    env_kwargs = {k: v for k, v in env_info["env_kwargs"].items() if k not in RECORDING_KWARGS}
    control_mode = env_kwargs.pop("control_mode")
    obs_mode = env_kwargs.pop("obs_mode", "state")
    return env_info["env_id"], env_kwargs, obs_mode, control_mode


class BestCheckpoint:
    """Keeps a copy (``best.pt`` beside the checkpoint) of the checkpoint that scored best in the evaluations made
    while training (by success_at_end, then success_once, then return), as ManiSkill's baselines keep their
    ``best_eval_success_at_end`` checkpoint: imitation learners overfit their demonstrations as they train on."""

    KEYS = ("success_at_end", "success_once", "episode_return")

    def __init__(self, checkpoint: Path):
        self.checkpoint, self.path = Path(checkpoint), Path(checkpoint).with_name("best.pt")
        self.score: Optional[tuple[float, ...]] = None

    def update(self, metrics: dict[str, float]) -> bool:
        """Copy the checkpoint if ``metrics`` (its evaluation) beat every earlier one; say whether it did."""
        score = tuple(metrics[key] for key in self.KEYS)
        if self.score is not None and score <= self.score:
            return False
        shutil.copyfile(self.checkpoint, self.path)
        self.score = score
        return True


def evaluate_policy(policy: Policy, env_id: str, env_kwargs: dict, seeds: Sequence[int]) -> dict[str, float]:
    """success_once, success_at_end and mean return of ``policy`` over ``seeds``, by the evaluation CLI's
    protocol (a fresh scene per seed, episodes to the time limit)."""
    import gymnasium as gym

    from mani_skill_space.rollout import run_episode

    kwargs = dict(env_kwargs, control_mode=policy.control_mode, obs_mode=policy.obs_mode)
    if kwargs["obs_mode"] in STATE_OBS_MODES:
        kwargs["render_backend"] = "none"
    env = gym.make(env_id, **kwargs)
    try:
        results = [run_episode(env, policy, seed) for seed in seeds]
    finally:
        env.close()
    return dict(
        success_once=float(np.mean([r.success_once for r in results])),
        success_at_end=float(np.mean([r.success_at_end for r in results])),
        episode_return=float(np.mean([r.episode_return for r in results])),
    )
