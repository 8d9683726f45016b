"""Checks of env kwargs' values: type, finiteness and range; every error names the kwarg and its valid choices or range.

The envs check their kwargs with these (``SpaceManipulationEnv.check_task_kwargs``) before building anything, so
suites and the command-line tools can check a configuration when they read it. Sim-free: no SAPIEN import.
Nothing is clamped or coerced: a value is accepted as given (ints become floats) or rejected.
"""

from __future__ import annotations

import math
import numbers
from typing import Any, Optional, Sequence

RUN_KWARGS = ("render_mode", "render_backend", "sim_backend", "reward_mode", "num_envs", "sensor_configs", "human_render_camera_configs", "viewer_camera_configs")
"""ManiSkill env kwargs that say how an env was run, not which task it was: what a trajectory file or a checkpoint
records beside the task's kwargs (ManiSkill's replay tool adds the camera configs it rendered with)."""


class KwargError(ValueError):
    """A bad env kwarg. ``kwarg`` names it, so that a suite can point at the line of that key."""

    def __init__(self, kwarg: str, message: str):
        super().__init__(message)
        self.kwarg = kwarg


def checked_choice(kwarg: str, value: Any, choices: Sequence[str], default: Optional[str] = None) -> str:
    """``value`` if it is one of ``choices``; None gives ``default`` (when there is one). An empty string is not
    None: it is rejected like any other unknown name."""
    if value is None and default is not None:
        return default
    if not isinstance(value, str) or value not in choices:
        raise KwargError(kwarg, f"unknown {kwarg} {value!r}; valid choices: {', '.join(choices)}")
    return value


def checked_number(kwarg: str, value: Any, low: float, high: float, *, low_open: bool = False, unit: str = "", meaning: str = "") -> float:
    """``value`` as a float if it is a finite real number (a bool is not) with ``low <= value <= high`` (``low <
    value`` when ``low_open``). ``unit`` and ``meaning`` make the error message clearer."""
    units = f" {unit}" if unit else ""
    valid = f"{kwarg} must be a finite number {'>' if low_open else '>='} {low:g}{units} and <= {high:g}{units}"
    explained = f" ({meaning})" if meaning else ""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise KwargError(kwarg, f"{valid}{explained}, got {type(value).__name__} {value!r}")
    number = float(value)
    if not math.isfinite(number) or number < low or number > high or (low_open and number == low):
        raise KwargError(kwarg, f"{valid}{explained}, got {value!r}")
    return number


def checked_natural(kwarg: str, value: Any, meaning: str = "") -> int:
    """``value`` if it is an int >= 0 (a bool is not)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 0:
        explained = f" ({meaning})" if meaning else ""
        raise KwargError(kwarg, f"{kwarg} must be an integer >= 0{explained}, got {value!r}")
    return int(value)
