"""The shipped checkpoints' manifest (``baselines/checkpoints/manifest.toml``): what each checkpoint is, how it was
trained and what it scored, checked against the checkpoint itself.

    [[checkpoints]]
    name = "bc_rocks_1000_levels"
    path = "bc_rocks_1000_levels.pt"          # relative to the manifest
    env_id = "SampleCollection-v1"
    kwargs = { domain = "mars", asset_source = "procedural", num_levels = 1000, start_level = 0 }
    obs_mode = "state"
    control_mode = "pd_ee_delta_pose"
    command = "python baselines/bc.py --demos ... --minutes 10"
    success_at_end = 0.5                     # measured with the evaluation CLI on the seeds below
    episodes = 100
    seed_start = 20000

Loading checks every entry: its keys, that the file is a readable checkpoint (tensors only, never code) and that the
env id, task kwargs, obs and control mode it records are the entry's.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mani_skill_space.learning.checkpoints import load_checkpoint
from mani_skill_space.protocol import task_kwargs

MANIFEST_KEYS = {"name", "path", "env_id", "kwargs", "obs_mode", "control_mode", "command", "success_at_end", "success_once", "episodes", "seed_start", "notes"}
REQUIRED_KEYS = MANIFEST_KEYS - {"success_once", "notes"}


class ManifestError(ValueError):
    pass


@dataclass(frozen=True)
class ManifestEntry:
    name: str
    path: Path
    env_id: str
    kwargs: dict[str, Any]
    obs_mode: str
    control_mode: str
    command: str
    success_at_end: float
    episodes: int
    seed_start: int
    success_once: float | None = None
    notes: str = ""

    @property
    def policy(self) -> str:
        return f"checkpoint:{self.path}"


def load_manifest(path: Path) -> list[ManifestEntry]:
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as error:
        raise ManifestError(f"{path}: {error}") from None
    entries = data.get("checkpoints")
    if set(data) != {"checkpoints"} or not isinstance(entries, list) or not entries:
        raise ManifestError(f"{path}: a manifest is a list of [[checkpoints]] tables and nothing else")
    loaded = [_entry(path, index, table) for index, table in enumerate(entries)]
    names = [entry.name for entry in loaded]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ManifestError(f"{path}: duplicate checkpoint names {duplicates}")
    return loaded


def _entry(path: Path, index: int, table: dict) -> ManifestEntry:
    where = f"{path}: [[checkpoints]] {index + 1}"
    unknown = sorted(set(table) - MANIFEST_KEYS)
    missing = sorted(REQUIRED_KEYS - set(table))
    if unknown or missing:
        raise ManifestError(f"{where}: " + "; ".join(filter(None, [f"unknown keys {unknown}" if unknown else "", f"missing keys {missing}" if missing else ""])) + f" (valid keys: {', '.join(sorted(MANIFEST_KEYS))})")
    for key in ("success_at_end", "success_once"):
        value = table.get(key, 0.0)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
            raise ManifestError(f"{where}: {key} must be a rate in [0, 1], got {value!r}")
    for key in ("episodes", "seed_start"):
        if isinstance(table[key], bool) or not isinstance(table[key], int) or table[key] < (1 if key == "episodes" else 0):
            raise ManifestError(f"{where}: {key} must be an integer >= {1 if key == 'episodes' else 0}, got {table[key]!r}")
    entry = ManifestEntry(**{**table, "path": (path.parent / table["path"]).resolve()})
    checkpoint = load_checkpoint(entry.path)
    recorded = dict(env_id=checkpoint["env_id"], kwargs=task_kwargs(checkpoint["env_kwargs"]), obs_mode=checkpoint["obs_mode"], control_mode=checkpoint["control_mode"])
    listed = dict(env_id=entry.env_id, kwargs=entry.kwargs, obs_mode=entry.obs_mode, control_mode=entry.control_mode)
    for key, value in listed.items():
        if recorded[key] != value:
            raise ManifestError(f"{where}: {key} is {value!r} but {entry.path.name} records {recorded[key]!r}")
    return entry
