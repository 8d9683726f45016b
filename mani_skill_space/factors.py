"""Factor shifts: env kwargs that move one factor of variation at a time, for held-out evaluation (sim-free).

Each is off by default (the env is the benchmark's) and checked like every other kwarg:

- ``sun_pitch_range`` (degrees, a ``(low, high)`` pair within [-90, 90]): the range the sun's pitch is drawn from
  (default the reference's 0-75); e.g. ``(-75, 0)`` lights the scene from the side the training range never does.
- ``camera_jitter`` (m, 0-0.2): the base camera's eye and the point it looks at each move by up to this much per
  axis, drawn per env at every reconfiguration from the episode seed.
- ``object_scale`` (0.5-2): the task's free object scaled about its centre of mass (tasks whose object fits
  nothing else: Sample Collection, Debris Capture).
- ``object_mass_scale`` (0.1-10): the graspable objects' density (so mass and inertia) times this.
- ``object_friction`` (0-2): the graspable objects' friction coefficient (default: the scene's, 1.0).
- ``gravity_scale`` (0-3): the domain's gravity times this (nothing changes in orbit).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from mani_skill_space.domains import SUN_PITCH_RANGE_DEG
from mani_skill_space.kwarg_checks import KwargError, checked_number
from mani_skill_space.procgen.asset import Asset, look_at

CAMERA_JITTER_STREAM = 0xCA3E7A
"""Mixed with the episode seed so that the camera's jitter is not correlated with the level's draws."""


@dataclass(frozen=True)
class FactorShifts:
    sun_pitch_range: tuple[float, float] = SUN_PITCH_RANGE_DEG
    camera_jitter: float = 0.0
    object_scale: float = 1.0
    object_mass_scale: float = 1.0
    object_friction: Optional[float] = None
    gravity_scale: float = 1.0

    @classmethod
    def from_checked(cls, checked: dict[str, Any]) -> "FactorShifts":
        return cls(**{field.name: checked[field.name] for field in dataclasses.fields(cls)})

    def scaled(self, asset: Asset) -> Asset:
        """``asset`` scaled by ``object_scale`` (the same asset when 1)."""
        return asset if self.object_scale == 1.0 else asset.scaled(self.object_scale)

    def with_material(self, asset: Asset) -> Asset:
        """``asset`` with its density times ``object_mass_scale`` and ``object_friction`` (the same asset when
        neither is shifted)."""
        if self.object_mass_scale == 1.0 and self.object_friction is None:
            return asset
        friction = asset.friction if self.object_friction is None else self.object_friction
        return dataclasses.replace(asset, density=asset.density * self.object_mass_scale, friction=friction)


def check_factor_kwargs(kwargs: dict[str, Any], supports_object_scale: bool, task: str) -> dict[str, Any]:
    """The factor-shift kwargs in ``kwargs`` checked (defaults for missing or None ones); ``object_scale`` other
    than 1 only where the task ``supports_object_scale``."""
    default = FactorShifts()
    checked: dict[str, Any] = dict(
        sun_pitch_range=_checked_range("sun_pitch_range", kwargs.get("sun_pitch_range"), default.sun_pitch_range, -90.0, 90.0, "degrees"),
        camera_jitter=checked_number("camera_jitter", _or(kwargs.get("camera_jitter"), 0.0), 0.0, 0.2, unit="m", meaning="the base camera's eye and target move up to this per axis"),
        object_scale=checked_number("object_scale", _or(kwargs.get("object_scale"), 1.0), 0.5, 2.0, meaning="size of the task's object relative to its generated size"),
        object_mass_scale=checked_number("object_mass_scale", _or(kwargs.get("object_mass_scale"), 1.0), 0.1, 10.0, meaning="density of the graspable objects relative to the default"),
        object_friction=None
        if kwargs.get("object_friction") is None
        else checked_number("object_friction", kwargs["object_friction"], 0.0, 2.0, meaning="friction coefficient of the graspable objects"),
        gravity_scale=checked_number("gravity_scale", _or(kwargs.get("gravity_scale"), 1.0), 0.0, 3.0, meaning="the domain's gravity times this"),
    )
    if checked["object_scale"] != 1.0 and not supports_object_scale:
        raise KwargError("object_scale", f"{task} has no object_scale: its objects must fit their sockets; tasks with it: SampleCollectionEnv, DebrisCaptureEnv")
    return checked


def _or(value: Any, default: Any) -> Any:
    return default if value is None else value


def _checked_range(kwarg: str, value: Any, default: tuple[float, float], low: float, high: float, unit: str) -> tuple[float, float]:
    if value is None:
        return default
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise KwargError(kwarg, f"{kwarg} must be a (low, high) pair of numbers within [{low:g}, {high:g}] {unit}, got {value!r}")
    pair = tuple(checked_number(kwarg, v, low, high, unit=unit) for v in value)
    if pair[0] > pair[1]:
        raise KwargError(kwarg, f"{kwarg} must be a (low, high) pair with low <= high, got {value!r}")
    return pair


def camera_offsets(episode_seeds: np.ndarray, jitter: float) -> Optional[np.ndarray]:
    """(n, 2, 3) offsets of each env's camera eye and look-at point, uniform within ``jitter`` per axis, from
    the episode seeds; None without jitter."""
    if jitter == 0.0:
        return None
    rows = []
    for seed in np.asarray(episode_seeds, dtype=np.int64):
        rng = np.random.default_rng([int(seed), CAMERA_JITTER_STREAM])
        rows.append(rng.uniform(-jitter, jitter, size=(2, 3)))
    return np.stack(rows)


def jittered_camera_frames(frame: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(n, 4, 4) poses of a camera at ``frame`` (4x4, SAPIEN's convention: it looks along its x axis) whose eye
    and the point 1 m ahead of it are moved by ``offsets`` (n, 2, 3)."""
    eye = frame[:3, 3]
    target = eye + frame[:3, 0]
    return np.stack([look_at(eye + eye_offset, target + target_offset) for eye_offset, target_offset in offsets])
