"""Communication delay: actions applied, and observations returned, a number of control steps late (sim-free).

``action_delay`` and ``observation_delay`` are an int number of control steps, or a ``(min, max)`` pair from which
each env draws its delay at every reset; ``delay_drift`` is the probability per step that an env's delays move by
one step up or down within their range. A ``DelayLine`` holds, per env, the last ``max + 1`` values sent (the value
sent ``max`` steps ago must still be there when the current one is written: with ``max`` slots the largest delay
would read the slot just overwritten, i.e. no delay at all). All tensors carry the ``num_envs`` leading dim.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Any, Callable, Optional, Union

import torch

from mani_skill_space.kwarg_checks import KwargError, checked_number

MAX_DELAY = 100
"""Control steps (5 s at 20 Hz)."""

Nested = Union[torch.Tensor, dict]


@dataclass(frozen=True)
class DelayRange:
    low: int = 0
    high: int = 0

    @property
    def active(self) -> bool:
        return self.high > 0


def check_delay_kwargs(kwargs: dict[str, Any]) -> dict[str, Any]:
    """``action_delay``, ``observation_delay`` (as ``DelayRange``) and ``delay_drift`` from ``kwargs``, checked."""
    checked: dict[str, Any] = {name: _checked_delay(name, kwargs.get(name)) for name in ("action_delay", "observation_delay")}
    drift = kwargs.get("delay_drift")
    checked["delay_drift"] = 0.0 if drift is None else checked_number("delay_drift", drift, 0.0, 1.0, meaning="probability per control step that an env's delay moves one step within its range")
    return checked


def _checked_delay(name: str, value: Any) -> DelayRange:
    valid = f"{name} must be an int in [0, {MAX_DELAY}] control steps or a (min, max) pair of them with min <= max"
    if value is None:
        return DelayRange()
    pair = (value, value) if not isinstance(value, (list, tuple)) else tuple(value)
    if len(pair) != 2 or not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) and 0 <= v <= MAX_DELAY for v in pair) or pair[0] > pair[1]:
        raise KwargError(name, f"{valid}, got {value!r}")
    return DelayRange(int(pair[0]), int(pair[1]))


class DelayLine:
    """Per-env ring buffers of the last ``high + 1`` values of a (nested dict of) batched tensor(s), read back
    ``delay`` steps late. ``steps[i]``: values written to env ``i`` since its reset; the reset's own value, if any,
    counts as written at step 0."""

    def __init__(self, num_envs: int, delays: DelayRange, device):
        self.delays = delays
        self.slots = delays.high + 1
        self.device = device
        self.delay = torch.full((num_envs,), delays.low, dtype=torch.long, device=device)
        self.steps = torch.zeros(num_envs, dtype=torch.long, device=device)
        self.has_first = torch.zeros(num_envs, dtype=torch.bool, device=device)
        self.buffer: Optional[Nested] = None

    def reset(self, env_idx: torch.Tensor, delay: torch.Tensor, first: Optional[Nested] = None) -> None:
        """Forget what envs ``env_idx`` were sent, give them ``delay`` (b,), and store ``first`` (their rows of a
        batched value, e.g. the reset observation) as the value read until ``delay`` newer ones were written."""
        self.delay[env_idx] = delay.to(self.device)
        self.steps[env_idx] = 0
        self.has_first[env_idx] = first is not None
        if first is not None:
            self._write(_map(lambda v: v[env_idx], first), env_idx)

    def push(self, value: Nested) -> None:
        """Write every env's newest value."""
        self.steps += 1
        self._write(value, torch.arange(len(self.steps), device=self.device))

    def read(self) -> tuple[Nested, torch.Tensor]:
        """Every env's value written ``delay`` writes ago (the reset's value while fewer were written since), and a
        mask (n,) of the envs for which there is none (no reset value, and no more writes than the delay): their rows
        are meaningless."""
        age = self.steps - self.delay
        missing = (age <= 0) & ~self.has_first
        slot = age.clamp(min=0) % self.slots
        rows = torch.arange(len(self.steps), device=self.device)
        return _map(lambda buffer: buffer[slot, rows], self.buffer), missing

    def drift(self, moves: torch.Tensor) -> None:
        """Move every env's delay by ``moves`` (n,) of -1, 0 or +1, kept within the range."""
        self.delay = (self.delay + moves.to(self.device)).clamp(self.delays.low, self.delays.high)

    def _write(self, rows: Nested, env_idx: torch.Tensor) -> None:
        """Store ``rows`` (the values of envs ``env_idx``, in that order) in each env's slot for its step count."""
        if self.buffer is None:
            self.buffer = _map(lambda v: torch.zeros((self.slots, len(self.steps), *v.shape[1:]), dtype=v.dtype, device=v.device), rows)
        slot = self.steps[env_idx] % self.slots
        _zip(lambda buffer, v: buffer.__setitem__((slot, env_idx), v), self.buffer, rows)


def _map(function: Callable[[torch.Tensor], torch.Tensor], value: Nested) -> Nested:
    if isinstance(value, dict):
        return {key: _map(function, item) for key, item in value.items()}
    return function(value)


def _zip(function: Callable[[torch.Tensor, torch.Tensor], Any], first: Nested, second: Nested) -> None:
    if isinstance(first, dict):
        for key in first:
            _zip(function, first[key], second[key])
    else:
        function(first, second)


def with_missing_replaced(value: Nested, missing: torch.Tensor, replacement: Nested) -> Nested:
    """``value`` with the rows ``missing`` (n,) taken from ``replacement`` (same structure)."""
    if not bool(missing.any()):
        return value
    if isinstance(value, dict):
        return {key: with_missing_replaced(value[key], missing, replacement[key]) for key in value}
    mask = missing.reshape(-1, *([1] * (value.dim() - 1)))
    return torch.where(mask, replacement.to(value.dtype), value)


def drift_moves(uniform: torch.Tensor, probability: float) -> torch.Tensor:
    """Per-env moves (-1, 0, +1) from uniform draws in [0, 1): down below ``probability / 2``, up below
    ``probability``."""
    return (uniform < probability / 2).long() * -1 + ((uniform >= probability / 2) & (uniform < probability)).long()
