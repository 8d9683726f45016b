"""Checkpoints: what a baseline saves, and the policy the evaluation CLI rebuilds from one.

A checkpoint (``torch.save`` of a dict of plain data and tensors) names its algorithm, env id, env kwargs, obs
and control mode and the network (class name, constructor kwargs, weights), so ``python -m
mani_skill_space.eval --policy checkpoint:PATH`` rebuilds the policy and scores it by the same protocol as every
other policy. Loading never executes code from the file (``weights_only=True``).
"""

from __future__ import annotations

import shutil
from collections import deque
from pathlib import Path
from typing import Optional

import torch
import torch.nn as nn

from mani_skill_space.learning.networks import MODELS, denoise
from mani_skill_space.learning.observations import encode_observation
from mani_skill_space.policy import Policy


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


class CheckpointError(ValueError):
    """A file that is not a readable checkpoint of ours (the message names the file)."""


CHECKPOINT_KEYS = ("algorithm", "model_class", "model_kwargs", "state_dict", "env_id", "env_kwargs", "obs_mode", "control_mode")


def load_checkpoint(path: Path, device: str = "cpu") -> dict:
    """A checkpoint's dict, loaded with ``weights_only=True``: tensors and plain data only, so a crafted file
    cannot run code. A missing, empty, corrupt or foreign file raises ``CheckpointError`` naming it."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"No checkpoint at {path}")
    try:
        checkpoint = torch.load(path, map_location=device, weights_only=True)
    except Exception as error:  # torch raises several types for corrupt, truncated or unsafe files
        raise CheckpointError(f"{path} is not a readable checkpoint ({type(error).__name__}: {str(error).splitlines()[0] if str(error) else 'no detail'})") from error
    missing = [key for key in CHECKPOINT_KEYS if not isinstance(checkpoint, dict) or key not in checkpoint]
    if missing:
        raise CheckpointError(f"{path} is not a mani-skill-space checkpoint (missing {', '.join(missing)})")
    return checkpoint


def load_model(checkpoint: dict, device: str = "cpu") -> nn.Module:
    if checkpoint["model_class"] not in MODELS:
        raise ValueError(f"Unknown model class {checkpoint['model_class']!r} in checkpoint; valid choices: {', '.join(MODELS)}")
    model = MODELS[checkpoint["model_class"]](**checkpoint["model_kwargs"])
    model.load_state_dict(checkpoint["state_dict"])
    return model.to(device).eval()


class CheckpointPolicy(Policy):
    """A trained baseline, deterministic (the mean action, or the diffusion policy's denoised chunk, its noise
    seeded by the episode's seed)."""

    def __init__(self, path: str, device: str = "cpu"):
        self.path = Path(path)
        self.checkpoint = load_checkpoint(self.path, device)
        self.device = torch.device(device)
        try:
            self.model = load_model(self.checkpoint, device)
        except (TypeError, RuntimeError) as error:  # constructor kwargs or weights another version of the model wrote
            raise CheckpointError(f"{self.path} does not fit this version's {self.checkpoint['model_class']} ({str(error).splitlines()[0]})") from error
        self.control_mode = self.checkpoint["control_mode"]
        self.obs_mode = self.checkpoint["obs_mode"]
        self.env_id = self.checkpoint["env_id"]
        self.training_condition = (self.env_id, dict(self.checkpoint["env_kwargs"]))
        """The env id and kwargs of the training environment (what a generalisation protocol calls ``train``)."""
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
        self.generator = torch.Generator(self.device).manual_seed(seed)
        """The diffusion policy's sampling noise, seeded by the episode: the same seed, the same rollout."""

    @torch.no_grad()
    def act(self, obs) -> torch.Tensor:
        encoded = encode_observation(obs, self.obs_mode, self.device)
        self._check_state_size(encoded["state"].shape[-1])
        if self.diffusion is None:
            return self.model.act(encoded)
        state = encoded["state"]
        while len(self.history) < self.history.maxlen:
            self.history.append(state)
        self.history.append(state)
        if not self.queue:
            chunk = denoise(self.model, self.scheduler, torch.stack(list(self.history), dim=1), self.diffusion["inference_steps"], self.generator)
            self.queue.extend(chunk[:, i] for i in range(self.diffusion["execute_horizon"]))
        return self.queue.popleft()

    def _check_state_size(self, size: int) -> None:
        """A model trained on another version of the env's observations (a feature added since) is refused by
        name rather than failing inside its first layer."""
        trained = self.checkpoint["model_kwargs"]["state_dim"]
        if size != trained:
            raise CheckpointError(
                f"{self.path} takes {trained} state observations and this version of {self.env_id} gives {size}: "
                "it was trained on another version of the env's observations; train it again"
            )


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

