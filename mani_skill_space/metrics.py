"""Episode outcomes and their summary statistics (sim-free)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Optional


@dataclass(frozen=True)
class EpisodeResult:
    seed: int
    success_once: bool
    success_at_end: bool
    episode_return: float
    episode_len: int
    """Steps until the first success, or all the steps the episode ran when it never succeeded."""
    failure: str = ""
    """Why a scripted policy did not succeed: the reason it gave up (e.g. a planning failure), or, for one that
    reports its phase (the oracles), ``time ran out while <phase>`` or ``the plan ended without success after <phase>``;
    empty otherwise."""
    stage: Optional[int] = None
    """The highest ``info["stage"]`` the episode reached (staged tasks: the sockets filled in Solar Panel Assembly,
    the samples or pegs placed in the multi-object tasks); None where the env reports no stage."""

    def to_dict(self) -> dict:
        return asdict(self)


def wilson_interval(successes: int, trials: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (95% by default)."""
    if trials <= 0:
        raise ValueError("the interval needs at least one trial")
    if not 0 <= successes <= trials:
        raise ValueError(f"successes ({successes}) must lie between 0 and trials ({trials})")
    p = successes / trials
    denominator = 1 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half_width = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / denominator
    return max(0.0, centre - half_width), min(1.0, centre + half_width)


def format_rate(rate: float, interval, decimals: int = 1) -> str:
    """A rate with its interval in percent, as the result tables print it: ``62.0% [52.2, 70.9]``."""
    return f"{100 * rate:.{decimals}f}% [{100 * interval[0]:.{decimals}f}, {100 * interval[1]:.{decimals}f}]"


def any_staged(summaries) -> bool:
    """Whether any of these summaries has a mean stage (a staged task's): result tables then add a stage column."""
    return any(summary.get("stage_mean") is not None for summary in summaries)


def stage_cell(summary: dict) -> str:
    """A summary's cell of the stage column: its mean highest stage, or ``-`` where its env reports no stage."""
    return "-" if summary.get("stage_mean") is None else f"{summary['stage_mean']:.2f}"


def summarize(results: list[EpisodeResult]) -> dict:
    n = len(results)
    once = sum(r.success_once for r in results)
    at_end = sum(r.success_at_end for r in results)
    return {
        "episodes": n,
        "success_once": once / n,
        "success_once_ci95": wilson_interval(once, n),
        "success_at_end": at_end / n,
        "success_at_end_ci95": wilson_interval(at_end, n),
        "return_mean": sum(r.episode_return for r in results) / n,
        "episode_len_mean": sum(r.episode_len for r in results) / n,
        "stage_mean": mean_stage(results),
    }


def mean_stage(results: list[EpisodeResult]) -> Optional[float]:
    """The mean of the highest stage each episode reached; None unless every episode reports a stage."""
    if not results or any(r.stage is None for r in results):
        return None
    return sum(r.stage for r in results) / len(results)
