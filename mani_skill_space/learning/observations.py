"""Observations as the baselines' networks take them."""

from __future__ import annotations

from typing import Any

import torch

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

