"""Speed of our envs on ManiSkill's GPU simulation against ManiSkill's own tasks, measured in the same run.

    python tests/gpu/bench_gpu.py
    python tests/gpu/bench_gpu.py --num-envs 256 --obs-modes state --json-path bench_gpu.json

The GPU counterpart of ``mani_skill_space.bench`` (one env on the CPU): for each env id and its ManiSkill peer
(``bench.REFERENCES``: PickCube-v1 or PegInsertionSide-v1), each number of parallel envs (256 and 1024) and each
observation mode (state; rgbd with 64x64 cameras), measures ``env.step`` throughput on ``physx_cuda``: env steps per
second summed over the parallel envs (num_envs * steps / seconds), random ``pd_ee_delta_pose`` actions (drawn on the
GPU before the clock starts), episode ends ignored (ManiSkill's profiler measures ``env.step`` alone the same way).
Ours and the peer are measured in interleaved rounds and the medians are reported, as in ``bench``. Prints a
markdown table with the ratio ours/peer and the seconds each env took to build (``gym.make``, which builds every
sub-scene's assets); ``--json-path`` also writes it as JSON.

Needs CUDA: without it, or with a bad input, it prints one line on stderr and exits with status 2 (``--debug``
shows the traceback; see ``mani_skill_space.cli_support``).
"""

from __future__ import annotations

import gc
import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Optional, Sequence

import gymnasium as gym
import torch

import mani_skill_space
from mani_skill_space.bench import REFERENCES, check_env_ids_and_obs_modes, env_kwargs, interleaved_medians
from mani_skill_space.cli_support import UserError, check_at_least, checking_inputs, run_cli, tyro_parser

TOOL = "bench-gpu"


@dataclass
class Args:
    env_ids: tuple[str, ...] = mani_skill_space.ENV_IDS
    num_envs: tuple[int, ...] = (256, 1024)
    obs_modes: tuple[str, ...] = ("state", "rgbd")
    steps: int = 200
    """Timed env steps per round in state mode (rgbd rounds use a quarter, at least 10)."""
    warmup_steps: int = 10
    """Untimed env steps after the reset of each round."""
    rounds: int = 3
    json_path: Optional[Path] = None


@dataclass
class Row:
    env_id: str
    reference_name: str
    num_envs: int
    obs_mode: str
    ours: float
    """env steps/s, summed over the parallel envs"""
    reference: float
    ours_build_s: float
    reference_build_s: float

    @property
    def ratio(self) -> float:
        return self.ours / self.reference if self.reference else float("nan")


@dataclass
class Report:
    device: str = ""
    rows: list[Row] = field(default_factory=list)


def make_env(env_id: str, obs_mode: str, num_envs: int) -> gym.Env:
    return gym.make(env_id, num_envs=num_envs, sim_backend="physx_cuda", **env_kwargs(obs_mode))


def built_env(env_id: str, obs_mode: str, num_envs: int) -> tuple[gym.Env, float]:
    """The env and the seconds ``gym.make`` took (every sub-scene built, GPU simulation initialised)."""
    start = time.perf_counter()
    env = make_env(env_id, obs_mode, num_envs)
    torch.cuda.synchronize()
    return env, time.perf_counter() - start


def close_env(env: gym.Env) -> None:
    env.close()
    del env
    gc.collect()
    torch.cuda.empty_cache()


def random_actions(env: gym.Env, count: int, seed: int) -> torch.Tensor:
    """(count, num_envs, action_dim) uniform in the action space's bounds, on the env's device."""
    base = env.unwrapped
    space = base.single_action_space
    low = torch.as_tensor(space.low, dtype=torch.float32, device=base.device)
    high = torch.as_tensor(space.high, dtype=torch.float32, device=base.device)
    generator = torch.Generator(device=base.device).manual_seed(seed)
    uniform = torch.rand((count, base.num_envs, low.shape[0]), generator=generator, device=base.device)
    return low + uniform * (high - low)


def steps_per_second(env: gym.Env, steps: int, warmup_steps: int, seed: int = 0) -> float:
    """Env steps per second summed over the parallel envs, for ``env.step`` alone."""
    base = env.unwrapped
    env.reset(seed=seed)
    actions = random_actions(env, warmup_steps + steps, seed)
    for action in actions[:warmup_steps]:
        env.step(action)
    torch.cuda.synchronize()
    start = time.perf_counter()
    for action in actions[warmup_steps:]:
        env.step(action)
    torch.cuda.synchronize()
    return base.num_envs * steps / (time.perf_counter() - start)


def bench_pair(env_id: str, obs_mode: str, num_envs: int, args: Args) -> Row:
    reference = REFERENCES[env_id]
    envs, build_seconds = {}, {}
    try:
        for name in (env_id, reference):
            envs[name], build_seconds[name] = built_env(name, obs_mode, num_envs)
        steps = args.steps if obs_mode == "state" else max(10, args.steps // 4)
        ours, theirs = interleaved_medians(lambda name: steps_per_second(envs[name], steps, args.warmup_steps), (env_id, reference), args.rounds)
    finally:
        for env in envs.values():
            close_env(env)
    return Row(env_id, reference, num_envs, obs_mode, ours, theirs, build_seconds[env_id], build_seconds[reference])


def format_report(report: Report) -> str:
    lines = [
        f"device: {report.device}",
        "",
        "| env | num_envs | obs | ours (env steps/s) | ManiSkill peer (env steps/s) | ratio ours/peer | build s (ours / peer) |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in report.rows:
        lines.append(
            f"| {row.env_id} | {row.num_envs} | {row.obs_mode} | {row.ours:.4g} | {row.reference_name}: {row.reference:.4g} "
            f"| {row.ratio:.2f}x | {row.ours_build_s:.1f} / {row.reference_build_s:.1f} |"
        )
    return "\n".join(lines)


def check_args(args: Args) -> None:
    """A ``ValueError`` naming the first bad input: an env id without a ManiSkill peer, an observation mode the envs
    reject, a count below 1."""
    check_env_ids_and_obs_modes(args.env_ids, args.obs_modes)
    for num_envs in args.num_envs:
        check_at_least("--num-envs", num_envs, 1)
    for name, value in (("--steps", args.steps), ("--rounds", args.rounds)):
        check_at_least(name, value, 1)
    check_at_least("--warmup-steps", args.warmup_steps, 0)


def check_cuda() -> None:
    if not torch.cuda.is_available():
        raise UserError("needs CUDA for ManiSkill's GPU simulation (physx_cuda), and torch.cuda.is_available() is False; run it on a machine with a GPU")


def main(args: Args) -> Report:
    with checking_inputs():
        check_args(args)
        check_cuda()
    report = Report(device=torch.cuda.get_device_name())
    for num_envs in args.num_envs:
        for obs_mode in args.obs_modes:
            for env_id in args.env_ids:
                report.rows.append(bench_pair(env_id, obs_mode, num_envs, args))
    print(format_report(report))
    if args.json_path is not None:
        payload = {"device": report.device, "rows": [asdict(row) | {"ratio": row.ratio} for row in report.rows]}
        args.json_path.write_text(json.dumps(payload, indent=1))
    return report


def cli(argv: Optional[Sequence[str]] = None) -> None:
    """``python tests/gpu/bench_gpu.py ARGS``."""
    run_cli(TOOL, tyro_parser(Args, TOOL, __doc__, prog="python tests/gpu/bench_gpu.py"), main, argv)


if __name__ == "__main__":
    cli()
