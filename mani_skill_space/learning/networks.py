"""The baselines' networks (ManiSkill's PPO agent, SAC's actor, a BC MLP, a diffusion policy's denoiser)."""

from __future__ import annotations

import math
from typing import Optional, Sequence

import torch
import torch.nn as nn

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
    """An MLP from (normalised, clipped) state to action; with ``observed`` (column indices of the state vector),
    from those columns only, so that a policy can be kept from features that would distract it."""

    def __init__(self, state_dim: int, action_dim: int, hidden: int = 512, depth: int = 3, observed: Optional[Sequence[int]] = None):
        super().__init__()
        if observed is not None and not all(0 <= i < state_dim for i in observed):
            raise ValueError(f"observed columns must lie in [0, {state_dim}): got {list(observed)}")
        self.net = mlp([state_dim if observed is None else len(observed), *([hidden] * depth), action_dim])
        self.register_buffer("obs_mean", torch.zeros(state_dim))
        self.register_buffer("obs_std", torch.ones(state_dim))
        # not saved with the weights: the checkpoint's model kwargs rebuild it, and it moves with the model
        self.register_buffer("observed", None if observed is None else torch.as_tensor(list(observed), dtype=torch.long), persistent=False)

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        normalized = _normalized(self, state)
        return self.net(normalized if self.observed is None else normalized[..., self.observed])

    def act(self, obs) -> torch.Tensor:
        return self(obs["state"])


class _ActionScaling:
    """A denoiser's action chunks live in [-1, 1] (DDPM's ``clip_sample``). With ``scale_actions`` the model maps that
    interval onto the demonstrations' per-dimension [min, max] (Chi et al.'s normalisation; buffers ``action_low`` and
    ``action_high``), for actions not already normalised, such as ``pd_joint_pos``'s joint targets in radians. A
    dimension that never varies maps to 0 and back to its one value."""

    def _register_action_scaling(self, action_dim: int, scale_actions: bool) -> None:
        self.scale_actions = scale_actions
        if scale_actions:
            self.register_buffer("action_low", -torch.ones(action_dim))
            self.register_buffer("action_high", torch.ones(action_dim))

    def fit_action_scaling(self, actions: torch.Tensor) -> None:
        """Set the range from demonstrated actions (..., action_dim)."""
        if self.scale_actions:
            flat = actions.reshape(-1, actions.shape[-1])
            self.action_low.copy_(flat.min(0).values)
            self.action_high.copy_(flat.max(0).values)

    def to_unit(self, actions: torch.Tensor) -> torch.Tensor:
        if not self.scale_actions:
            return actions
        centre, half_span = self._centre_and_half_span()
        return (actions - centre) / half_span

    def from_unit(self, chunk: torch.Tensor) -> torch.Tensor:
        if not self.scale_actions:
            return chunk
        centre, half_span = self._centre_and_half_span()
        return centre + chunk * half_span

    def _centre_and_half_span(self) -> tuple[torch.Tensor, torch.Tensor]:
        return (self.action_high + self.action_low) / 2.0, ((self.action_high - self.action_low) / 2.0).clamp_min(1e-6)


class DiffusionNoisePredictor(_ActionScaling, nn.Module):
    """The diffusion policy's denoiser: predicts the noise in an action chunk, given the observation history
    and the diffusion step (an MLP version of Chi et al.'s conditional network)."""

    def __init__(self, state_dim: int, action_dim: int, obs_horizon: int, action_horizon: int, hidden: int = 512, step_features: int = 64, scale_actions: bool = False):
        super().__init__()
        self._register_action_scaling(action_dim, scale_actions)
        self.state_dim, self.action_dim, self.obs_horizon, self.action_horizon = state_dim, action_dim, obs_horizon, action_horizon
        self.step_features = step_features
        self.net = mlp([action_dim * action_horizon + state_dim * obs_horizon + step_features, hidden, hidden, hidden, action_dim * action_horizon], nn.Mish)
        self.register_buffer("obs_mean", torch.zeros(state_dim))
        self.register_buffer("obs_std", torch.ones(state_dim))

    def forward(self, noisy_actions: torch.Tensor, step: torch.Tensor, obs_history: torch.Tensor) -> torch.Tensor:
        n = noisy_actions.shape[0]
        conditioning = _normalized(self, obs_history).reshape(n, -1)
        out = self.net(torch.cat([noisy_actions.reshape(n, -1), conditioning, step_embedding(step, n, self.step_features)], dim=-1))
        return out.reshape(n, self.action_horizon, self.action_dim)


def step_embedding(step: torch.Tensor, n: int, features: int) -> torch.Tensor:
    """(n, features) sinusoidal embedding of the diffusion step (a scalar, or one per sample)."""
    half = features // 2
    frequencies = torch.exp(-math.log(10000.0) * torch.arange(half, device=step.device) / half)
    angles = step.float().reshape(-1, 1) * frequencies[None]
    return torch.cat([angles.sin(), angles.cos()], dim=-1).expand(n, -1)


def _normalized(model: nn.Module, obs: torch.Tensor) -> torch.Tensor:
    """Observations (..., state_dim) normalized by the model's statistics (its ``obs_mean`` and ``obs_std``
    buffers), clipped to +-OBS_CLIP."""
    return torch.clamp((obs - model.obs_mean) / model.obs_std, -OBS_CLIP, OBS_CLIP)


class _ConditionedResidualBlock(nn.Module):
    """Two 1-D convolutions (group norm, Mish) over the action chunk's time axis, the second's input scaled and
    shifted by the conditioning (FiLM), with a residual connection."""

    def __init__(self, channels_in: int, channels_out: int, conditioning: int, kernel: int = 5, groups: int = 8):
        super().__init__()
        self.first = _convolution(channels_in, channels_out, kernel, groups)
        self.second = _convolution(channels_out, channels_out, kernel, groups)
        self.film = nn.Sequential(nn.Mish(), nn.Linear(conditioning, 2 * channels_out))
        self.residual = nn.Conv1d(channels_in, channels_out, 1) if channels_in != channels_out else nn.Identity()

    def forward(self, x: torch.Tensor, conditioning: torch.Tensor) -> torch.Tensor:
        scale, shift = self.film(conditioning).unsqueeze(-1).chunk(2, dim=1)
        return self.second(self.first(x) * scale + shift) + self.residual(x)


def _convolution(channels_in: int, channels_out: int, kernel: int, groups: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv1d(channels_in, channels_out, kernel, padding=kernel // 2), nn.GroupNorm(groups, channels_out), nn.Mish())


class DiffusionUnetNoisePredictor(_ActionScaling, nn.Module):
    """The diffusion policy's denoiser as Chi et al. (and ManiSkill's diffusion policy baseline) build it: a 1-D
    UNet over the action chunk's time axis, every residual block conditioned (FiLM) on the diffusion step's
    embedding and the observation history. ``action_horizon`` must be divisible by 2 ** (len(channels) - 1)."""

    def __init__(self, state_dim: int, action_dim: int, obs_horizon: int, action_horizon: int, channels: Sequence[int] = (64, 128, 256), step_features: int = 64, scale_actions: bool = False):
        super().__init__()
        self._register_action_scaling(action_dim, scale_actions)
        if action_horizon % 2 ** (len(channels) - 1):
            raise ValueError(f"action_horizon {action_horizon} must be divisible by {2 ** (len(channels) - 1)} for {len(channels)} UNet levels")
        self.state_dim, self.action_dim, self.obs_horizon, self.action_horizon = state_dim, action_dim, obs_horizon, action_horizon
        self.step_features = step_features
        conditioning = step_features + state_dim * obs_horizon
        self.step_mlp = nn.Sequential(nn.Linear(step_features, 4 * step_features), nn.Mish(), nn.Linear(4 * step_features, step_features))
        widths = [action_dim, *channels]
        self.down = nn.ModuleList()
        for level, (width_in, width_out) in enumerate(zip(widths[:-1], widths[1:])):
            last = level == len(channels) - 1
            self.down.append(nn.ModuleList([
                _ConditionedResidualBlock(width_in, width_out, conditioning),
                _ConditionedResidualBlock(width_out, width_out, conditioning),
                nn.Identity() if last else nn.Conv1d(width_out, width_out, 3, stride=2, padding=1),
            ]))
        self.middle = nn.ModuleList([_ConditionedResidualBlock(channels[-1], channels[-1], conditioning) for _ in range(2)])
        self.up = nn.ModuleList()
        for width_in, width_out in reversed(list(zip(channels[:-1], channels[1:]))):
            self.up.append(nn.ModuleList([
                _ConditionedResidualBlock(2 * width_out, width_in, conditioning),
                _ConditionedResidualBlock(width_in, width_in, conditioning),
                nn.ConvTranspose1d(width_in, width_in, 4, stride=2, padding=1),
            ]))
        self.out = nn.Sequential(_convolution(channels[0], channels[0], 5, 8), nn.Conv1d(channels[0], action_dim, 1))
        self.register_buffer("obs_mean", torch.zeros(state_dim))
        self.register_buffer("obs_std", torch.ones(state_dim))

    def forward(self, noisy_actions: torch.Tensor, step: torch.Tensor, obs_history: torch.Tensor) -> torch.Tensor:
        n = noisy_actions.shape[0]
        conditioning = torch.cat([self.step_mlp(step_embedding(step, n, self.step_features)), _normalized(self, obs_history).reshape(n, -1)], dim=-1)
        x = noisy_actions.transpose(1, 2)  # (n, action_dim, action_horizon): convolve over time
        skips = []
        for first, second, downsample in self.down:
            x = second(first(x, conditioning), conditioning)
            skips.append(x)
            x = downsample(x)
        for block in self.middle:
            x = block(x, conditioning)
        for first, second, upsample in self.up:
            x = upsample(second(first(torch.cat([x, skips.pop()], dim=1), conditioning), conditioning))
        return self.out(x).transpose(1, 2)


MODELS = {cls.__name__: cls for cls in (GaussianActorCritic, SquashedGaussianActor, BehaviourCloningPolicy, DiffusionNoisePredictor, DiffusionUnetNoisePredictor)}


def denoise(model: _ActionScaling, scheduler, obs_history: torch.Tensor, inference_steps: int, generator: Optional[torch.Generator] = None) -> torch.Tensor:
    """Sample an action chunk (n, action_horizon, action_dim) by running the reverse diffusion, in the env's action
    units (the denoiser's ``from_unit``); ``generator`` draws the initial noise and every step's noise (the same generator state, the same chunk)."""
    actions = torch.randn((obs_history.shape[0], model.action_horizon, model.action_dim), generator=generator, device=obs_history.device)
    scheduler.set_timesteps(inference_steps)
    for step in scheduler.timesteps:
        noise = model(actions, step.to(obs_history.device), obs_history)
        actions = scheduler.step(noise, step, actions, generator=generator).prev_sample
    return model.from_unit(actions.clamp(-1.0, 1.0))

