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


# ---------------------------------------------------------------------- the state vector's layout
def state_layout(obs_dict: dict, prefix: str = "", start: int = 0) -> dict[str, slice]:
    """Where each entry of a state observation lies in the flat vector of ManiSkill's ``state`` obs mode, from the
    same observation as a ``state_dict`` (batched tensors): ``{"agent/qpos": slice(0, 9), ..., "extra/tcp_pos": ...}``,
    in the order ``mani_skill.utils.common.flatten_state_dict`` concatenates them (insertion order, depth first; an
    (n,) tensor is one column), the first from column ``start``."""
    layout: dict[str, slice] = {}
    for key, value in obs_dict.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            inner = state_layout(value, f"{name}/", start)
            layout.update(inner)
            start = max((s.stop for s in inner.values()), default=start)
            continue
        width = 1 if value.ndim == 1 else int(value.shape[1])
        layout[name] = slice(start, start + width)
        start += width
    return layout


def observed_dims(layout: dict[str, slice], keys) -> list[int]:
    """The state vector's columns of the entries ``keys`` (names in ``layout``, e.g. ``extra/tcp_pos``), in the
    vector's order; an unknown name raises ``ValueError`` naming the valid ones."""
    unknown = [key for key in keys if key not in layout]
    if unknown:
        raise ValueError(f"Unknown state observation entr{'y' if len(unknown) == 1 else 'ies'} {', '.join(map(repr, unknown))}; valid choices: {', '.join(layout)}")
    return sorted(i for key in set(keys) for i in range(layout[key].start, layout[key].stop))
