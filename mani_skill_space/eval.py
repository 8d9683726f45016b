"""Evaluate policies on a benchmark suite.

    mani-skill-space eval --suite smoke --policy oracle random
    python -m mani_skill_space.eval --suite tasks/smoke.toml --policy oracle random

Every configuration of the suite runs its episodes (one seed each, seeds from the suite) in worker processes
and reports success_once and success_at_end with 95% Wilson intervals, the mean return (in the env's reward
mode, ``normalized_dense`` unless the suite says otherwise) and the mean episode length (steps until the first
success, or the whole episode). Results go to ``results.json`` and ``results.md`` in the output folder; the
table is also printed. The same suite and policies give the same numbers.

Policies: ``random``, ``zero``, ``oracle`` (the motion-planning solution of each task), ``oracle-ee`` (the same
acting in ``pd_ee_delta_pose``) or ``module:callable``
(see ``mani_skill_space.policies``). A policy with a ``control_mode`` gets its env made in that mode.

``--protocol NAME`` scores each policy on a generalisation protocol instead (``mani_skill_space.protocol``,
shipped ones in ``tasks/generalisation/``): one row per policy (its training condition, recorded in a checkpoint),
one column per test condition plus the in-distribution one, the generalisation gap of every test with Newcombe's
interval; ``matrix.json``, ``matrix.md`` and ``matrix.png`` (a heat map) in the output folder.

The suite or protocol (its env ids and kwargs), the policies and the counts are checked before any worker starts;
a bad one is one line on stderr and exit status 2 (``--debug`` shows the traceback; see
``mani_skill_space.cli_support``).
"""

from __future__ import annotations

import importlib
import json
import math
import dataclasses
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Optional, Sequence

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
from tqdm import tqdm

from mani_skill_space.cli_support import UserError, check_at_least, checking_inputs, one_line, run_cli, tyro_parser
from mani_skill_space.learning.checkpoints import CheckpointError
from mani_skill_space.metrics import EpisodeResult, any_staged, format_rate, stage_cell, summarize
from mani_skill_space.policies import load_policy
from mani_skill_space.protocol import Protocol, heat_map, load_protocol, markdown_matrix, matrix_row, protocol_suite
from mani_skill_space.rollout import evaluation_env_kwargs, run_episode
from mani_skill_space.suites import Configuration, Suite, load_suite


@dataclass
class Args:
    suite: Optional[Path] = None
    """A suite: the name of a shipped suite (e.g. smoke) or the path of a .toml file."""
    protocol: Optional[Path] = None
    """Instead of a suite, a generalisation protocol: the name of a shipped one (e.g. levels) or a .toml file."""
    policy: tuple[str, ...] = ("oracle",)
    """One or more policies: random, zero, oracle, oracle-ee, checkpoint:PATH or module:callable."""
    output_dir: Path = Path("outputs/eval")
    num_workers: int = os.cpu_count() or 1
    video: int = 0
    """Save videos of the first N episodes of every configuration and policy."""
    episodes: Optional[int] = None
    """Run only the first N seeds of every configuration (a quick look; the suite's counts otherwise)."""


@dataclass(frozen=True)
class Chunk:
    configuration: Configuration
    policy: str
    seeds: tuple[int, ...]
    video_dir: Optional[str] = None


_ENVS: dict[str, gym.Env] = {}


def _cached_env(env_id: str, kwargs: dict) -> gym.Env:
    """Workers keep their last env: consecutive chunks of a configuration reuse it (every episode rebuilds the
    scene from its seed anyway)."""
    key = json.dumps([env_id, kwargs], sort_keys=True)
    if key not in _ENVS:
        for env in _ENVS.values():
            env.close()
        _ENVS.clear()
        _ENVS[key] = gym.make(env_id, **kwargs)
    return _ENVS[key]


def worker_torch_threads(num_workers: int) -> int:
    """Torch threads per evaluation worker: the machine's cores shared among the workers. (Each worker's torch
    otherwise takes every core: two workers' learned policies, e.g. a diffusion policy's UNet, then ran 25 times
    slower on two cores than with one thread each.)"""
    return max(1, (os.cpu_count() or 1) // num_workers)


def limit_torch_threads(threads: int) -> None:
    import torch

    torch.set_num_threads(threads)


def run_chunk(chunk: Chunk) -> list[EpisodeResult]:
    import mani_skill_space  # noqa: F401  (registers the envs in a spawned worker)

    policy = load_policy(chunk.policy)
    kwargs = evaluation_env_kwargs(chunk.configuration.kwargs, policy, render=chunk.video_dir is not None)
    env = _cached_env(chunk.configuration.env_id, kwargs)
    results = []
    for seed in chunk.seeds:
        frames: list[np.ndarray] = []
        record = (lambda: frames.append(env.render()[0].cpu().numpy())) if chunk.video_dir else None
        results.append(run_episode(env, policy, seed, on_step=record))
        if chunk.video_dir:
            Path(chunk.video_dir).mkdir(parents=True, exist_ok=True)
            imageio.mimsave(Path(chunk.video_dir) / f"{chunk.policy.replace(':', '_')}_seed{seed}.mp4", frames, fps=20)
    return results


def plan_chunks(suite: Suite, policies: tuple[str, ...], args: Args) -> list[Chunk]:
    chunks = []
    for configuration in suite.configurations:
        seeds = configuration.seeds[: args.episodes] if args.episodes else configuration.seeds
        for policy in policies:
            video_dir = str(args.output_dir / "videos" / _slug(configuration.name)) if args.video else None
            recorded, rest = seeds[: args.video], seeds[args.video :]
            if recorded:
                chunks.append(Chunk(configuration, policy, tuple(recorded), video_dir))
            size = max(1, math.ceil(len(rest) / (2 * max(1, args.num_workers))))
            chunks += [Chunk(configuration, policy, tuple(rest[i : i + size])) for i in range(0, len(rest), size)]
    return chunks


def check_policy(spec: str) -> None:
    """Load the policy ``spec`` names, as the workers will: a ``ValueError`` or ``OSError`` when it names no policy
    (an unknown name, a ``module:callable`` that does not import or exist, a missing checkpoint)."""
    module_name, colon, attribute = spec.partition(":")
    if colon and module_name != "checkpoint":
        try:
            module = importlib.import_module(module_name)
        except ImportError as error:
            raise ValueError(f"policy {spec!r}: cannot import module {module_name!r} ({error})") from None
        if not hasattr(module, attribute):
            raise ValueError(f"policy {spec!r}: module {module_name!r} has no {attribute!r}")
    load_policy(spec)


def check_args(args: Args) -> Suite | Protocol:
    """The suite or protocol ``args`` name, loaded and checked (env ids and kwargs), after checking the policies
    and counts; for a protocol, also every policy's row (a checkpoint's training condition with each test)."""
    check_at_least("--num-workers", args.num_workers, 1)
    check_at_least("--video", args.video, 0)
    check_at_least("--episodes", args.episodes, 1)
    if not args.policy:
        raise ValueError("--policy needs at least one policy: random, zero, oracle, oracle-ee, checkpoint:PATH or module:callable")
    if (args.suite is None) == (args.protocol is None):
        raise ValueError("give either --suite (a benchmark suite) or --protocol (a generalisation protocol)")
    for policy in args.policy:
        check_policy(policy)
    if args.suite is not None:
        return load_suite(args.suite)
    protocol = load_protocol(args.protocol)
    for policy in args.policy:
        protocol_suite(protocol, *training_condition(protocol, policy))
    return protocol


def training_condition(protocol: Protocol, spec: str) -> tuple[str, dict]:
    """The env id and kwargs the policy ``spec`` was trained in: what it records (a checkpoint's), else the
    protocol's ``[train]``."""
    recorded = getattr(load_policy(spec), "training_condition", None)
    return recorded if recorded is not None else (protocol.env_id, protocol.train_kwargs)


def evaluate_protocol(protocol: Protocol, args: Args) -> dict:
    """Every policy's row of the protocol's matrix (each row's cells run as a suite)."""
    rows = []
    for policy in args.policy:
        env_id, kwargs = training_condition(protocol, policy)
        report = evaluate(protocol_suite(protocol, env_id, kwargs), dataclasses.replace(args, policy=(policy,)))
        rows.append(matrix_row(policy, kwargs, report["rows"]))
    columns = [c.name for c in protocol_suite(protocol, protocol.env_id, protocol.train_kwargs).configurations]
    return {"protocol": protocol.name, "protocol_file": str(protocol.path), "env_id": protocol.env_id, "metric": "success_at_end", "columns": columns, "rows": rows}


def evaluate(suite: Suite, args: Args) -> dict:
    chunks = plan_chunks(suite, args.policy, args)
    results: dict[tuple[str, str], list[EpisodeResult]] = {}
    threads = (worker_torch_threads(args.num_workers),)
    with ProcessPoolExecutor(max_workers=args.num_workers, mp_context=get_context("spawn"), initializer=limit_torch_threads, initargs=threads) as pool:
        futures = {pool.submit(run_chunk, chunk): chunk for chunk in chunks}
        with tqdm(total=sum(len(c.seeds) for c in chunks), desc=f"eval {suite.name}", unit="episode") as progress:
            for future in as_completed(futures):
                chunk = futures[future]
                try:
                    episodes = future.result()
                except CheckpointError as error:  # found once the env is made: a checkpoint from another version
                    raise UserError(one_line(error)) from error
                results.setdefault((chunk.configuration.name, chunk.policy), []).extend(episodes)
                progress.update(len(chunk.seeds))
    return _report(suite, args.policy, results)


def _report(suite: Suite, policies: tuple[str, ...], results: dict) -> dict:
    rows = []
    for configuration in suite.configurations:
        for policy in policies:
            row = {"configuration": configuration.name, "env_id": configuration.env_id, "kwargs": configuration.kwargs, "policy": policy}
            episodes = sorted(results[(configuration.name, policy)], key=lambda r: r.seed)
            row.update(status="ok", summary=summarize(episodes), episodes=[e.to_dict() for e in episodes])
            rows.append(row)
    return {"suite": suite.name, "suite_file": str(suite.path), "policies": list(policies), "rows": rows}


def markdown_table(report: dict) -> str:
    """The report as a table; staged tasks (rows with a ``stage_mean``) add a column with the mean highest stage."""
    staged = any_staged(row["summary"] for row in report["rows"])
    stage_header = (" stage |", "---|") if staged else ("", "")
    lines = [
        f"Suite `{report['suite']}`: success rates with 95% Wilson intervals.",
        "",
        "| configuration | policy | episodes | success_once | success_at_end | return | episode_len |" + stage_header[0],
        "|---|---|---|---|---|---|---|" + stage_header[1],
    ]
    for row in report["rows"]:
        s = row["summary"]
        line = (
            f"| {row['configuration']} | {row['policy']} | {s['episodes']} | {format_rate(s['success_once'], s['success_once_ci95'])} "
            f"| {format_rate(s['success_at_end'], s['success_at_end_ci95'])} | {s['return_mean']:.2f} | {s['episode_len_mean']:.1f} |"
        )
        if staged:
            line += f" {stage_cell(s)} |"
        lines.append(line)
    return "\n".join(lines)


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def main(args: Args) -> dict:
    with checking_inputs():
        suite = check_args(args)
    output = args.output_dir
    output.mkdir(parents=True, exist_ok=True)
    if isinstance(suite, Protocol):
        return write_matrix(evaluate_protocol(suite, args), output)
    report = evaluate(suite, args)
    (output / "results.json").write_text(json.dumps(report, indent=1) + "\n")
    table = markdown_table(report)
    (output / "results.md").write_text(table + "\n")
    print(table)
    print(f"\nresults: {output / 'results.json'} and {output / 'results.md'}")
    return report


def write_matrix(matrix: dict, output: Path) -> dict:
    (output / "matrix.json").write_text(json.dumps(matrix, indent=1) + "\n")
    table = markdown_matrix(matrix)
    (output / "matrix.md").write_text(table + "\n")
    print(table)
    image = heat_map(matrix, output / "matrix.png")
    print(f"\nresults: {output / 'matrix.json'}, {output / 'matrix.md'}" + (f" and {image}" if image else " (no heat map: it needs matplotlib)"))
    return matrix


def cli(argv: Optional[Sequence[str]] = None) -> None:
    """``mani-skill-space eval ARGS`` (and ``python -m mani_skill_space.eval ARGS``)."""
    run_cli("eval", tyro_parser(Args, "eval", __doc__), main, argv)


if __name__ == "__main__":
    cli()
