"""Demonstrations in ManiSkill's trajectory format, as the imitation baselines read them."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from mani_skill_space.kwarg_checks import RUN_KWARGS


def load_demonstrations(path: Path, success_only: bool = True, limit: Optional[int] = None) -> tuple[list[dict[str, np.ndarray]], dict]:
    """Episodes of a ManiSkill trajectory file (``.h5`` + ``.json``, state observations): a list of
    ``{"obs": (T + 1, d), "actions": (T, a)}`` (with ``"success"`` and ``"terminated"``, (T,) booleans, and
    ``"rewards"``, (T,) floats, where the file records them, as ManiSkill's ``RecordEpisode`` does; the reward is
    the one of the file's ``reward_mode``) and the file's env info (env id, env kwargs)."""
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
            episode_data = {"obs": np.asarray(obs, dtype=np.float32), "actions": np.asarray(trajectory["actions"], dtype=np.float32)}
            episode_data.update({flag: np.asarray(trajectory[flag], dtype=bool) for flag in ("success", "terminated") if flag in trajectory})
            if "rewards" in trajectory:
                episode_data["rewards"] = np.asarray(trajectory["rewards"], dtype=np.float32)
            episodes.append(episode_data)
            if limit is not None and len(episodes) >= limit:
                break
    if not episodes:
        raise ValueError(f"{path} holds no {'successful ' if success_only else ''}episodes")
    return episodes, meta["env_info"]


def load_labelled_states(path: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    """States labelled by an expert (``baselines/dagger.py``'s ``.h5`` + ``.json``): observations (N, d), the
    expert's actions (N, a) and the env info (as a trajectory file's)."""
    import json

    import h5py

    path = Path(path)
    meta = json.loads(path.with_suffix(".json").read_text())
    with h5py.File(path, "r") as data:
        if "obs" not in data or "actions" not in data:
            raise ValueError(f"{path} holds no labelled states (datasets 'obs' and 'actions'); write it with baselines/dagger.py")
        obs, actions = np.asarray(data["obs"], dtype=np.float32), np.asarray(data["actions"], dtype=np.float32)
    if len(obs) != len(actions) or not len(obs):
        raise ValueError(f"{path} holds {len(obs)} states and {len(actions)} actions; expected as many of each, at least one")
    return obs, actions, meta["env_info"]


RECORDING_KWARGS = RUN_KWARGS
"""Env kwargs a trajectory file records that belong to how it was recorded, not to the task."""


def task_of_demonstrations(env_info: dict) -> tuple[str, dict, str, str]:
    """Env id, task kwargs (domain, asset source, ...), obs mode and control mode of a trajectory file's env info."""
    env_kwargs = {k: v for k, v in env_info["env_kwargs"].items() if k not in RECORDING_KWARGS}
    control_mode = env_kwargs.pop("control_mode")
    obs_mode = env_kwargs.pop("obs_mode", "state")
    return env_info["env_id"], env_kwargs, obs_mode, control_mode

