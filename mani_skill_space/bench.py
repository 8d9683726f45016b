"""Speed of our envs against ManiSkill's own tasks, measured in the same run (ratios, not seconds).

    mani-skill-space bench
    python -m mani_skill_space.bench

Measures env steps/s (random ``pd_ee_delta_pose`` actions, physx_cpu, one env) in state and rgbd-64 modes,
the time of a reconfigure (scene rebuild), env steps/s summed over a ``gymnasium.vector.AsyncVectorEnv`` of 2
spawned workers (what a 2-core machine gives a learner; episode ends reset), and the generation time of each
procedural asset. Each env is
measured in several interleaved rounds and the median is reported, because these machines are noisy.

The env ids, observation modes and counts are checked before anything is measured; a bad one is one line on stderr
and exit status 2 (``--debug`` shows the traceback; see ``mani_skill_space.cli_support``).
"""

from __future__ import annotations

import json
import statistics
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Optional, Sequence

import gymnasium as gym

import mani_skill_space
from mani_skill_space.cli_support import check_at_least, checking_inputs, run_cli, tyro_parser
from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.domains import DOMAINS
from mani_skill_space.envs import task_class
from mani_skill_space.envs.multi_peg_in_hole_assembly import module_positions, pair_arm_planning
from mani_skill_space.envs.peg_in_hole_assembly import reachable_peg_hole_pair
from mani_skill_space.envs.solar_panel_assembly import reachable_solar_set
from mani_skill_space.procgen.debris import make_debris
from mani_skill_space.procgen.mounts import make_rover, make_station
from mani_skill_space.procgen.peg_hole import DEFAULT_CLEARANCE, make_peg_hole_pair
from mani_skill_space.procgen.rock import make_rock
from mani_skill_space.procgen.solar_panel import make_panel, make_socket_base, make_solar_layout, make_solar_pegs
from mani_skill_space.procgen.terrain import make_terrain

REFERENCES = {
    "SampleCollection-v1": "PickCube-v1",
    "PegInHoleAssembly-v1": "PegInsertionSide-v1",
    "DebrisCapture-v1": "PickCube-v1",
    "SolarPanelAssembly-v1": "PegInsertionSide-v1",
    "MultiSampleCollection-v1": "PickCube-v1",
    "MultiPegInHoleAssembly-v1": "PegInsertionSide-v1",
}
"""The ManiSkill task each of our envs is compared with."""


@dataclass
class Args:
    env_ids: tuple[str, ...] = mani_skill_space.ENV_IDS
    obs_modes: tuple[str, ...] = ("state", "rgbd")
    steps: int = 300
    """Env steps per round in state mode (rgbd rounds use a tenth)."""
    rounds: int = 3
    reconfigures: int = 5
    asset_repeats: int = 20
    vector_workers: int = 2
    """Workers of the vectorised row (``gymnasium.vector.AsyncVectorEnv``, spawned; state); 0 leaves it out."""
    json_path: Optional[Path] = None


@dataclass
class Row:
    name: str
    ours: float
    reference_name: str
    reference: float
    unit: str
    target: str = ""

    @property
    def ratio(self) -> float:
        return self.ours / self.reference if self.reference else float("nan")


@dataclass
class Report:
    rows: list[Row] = field(default_factory=list)
    assets_ms: dict[str, float] = field(default_factory=dict)


SENSOR_SIZE = 64


def env_kwargs(obs_mode: str) -> dict:
    """What the bench makes every env with (ours and ManiSkill's alike): random ``pd_ee_delta_pose`` actions,
    64x64 cameras, no renderer in state mode."""
    kwargs = dict(obs_mode=obs_mode, control_mode="pd_ee_delta_pose", sensor_configs=dict(width=SENSOR_SIZE, height=SENSOR_SIZE))
    if obs_mode == "state":
        kwargs["render_backend"] = "none"
    return kwargs


def make_env(env_id: str, obs_mode: str):
    return gym.make(env_id, **env_kwargs(obs_mode))


def make_vector_env(env_id: str, workers: int):
    """``gymnasium.vector.AsyncVectorEnv`` of ``workers`` single state envs in spawned processes (auto-resetting),
    as ManiSkill runs CPU envs in parallel."""
    from mani_skill_space.learning.vector_env import CPUEnvFactory

    return gym.vector.AsyncVectorEnv([CPUEnvFactory(env_id, env_kwargs("state")) for _ in range(workers)], context="spawn")


def vector_steps_per_second(env, steps: int) -> float:
    """Env steps per second summed over the workers of ``make_vector_env`` (episode ends reset the finished
    workers' envs, reconfigures included)."""
    env.reset(seed=list(range(env.num_envs)))
    env.action_space.seed(0)
    start = time.perf_counter()
    for _ in range(steps):
        env.step(env.action_space.sample())
    return steps * env.num_envs / (time.perf_counter() - start)


def steps_per_second(env, steps: int, with_resets: bool = False) -> float:
    """Random-action env steps per second; like ManiSkill's profiler, either ``env.step`` alone (episode ends
    ignored) or ``env.step`` plus the resets that episode ends call for (reconfigures included)."""
    env.reset(seed=0)
    env.action_space.seed(0)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if with_resets and bool(terminated.any() or truncated.any()):
            env.reset()
    return steps / (time.perf_counter() - start)


def reconfigure_seconds(env, count: int) -> float:
    durations = []
    for seed in range(count):
        start = time.perf_counter()
        env.reset(seed=seed, options=dict(reconfigure=True))
        durations.append(time.perf_counter() - start)
    return statistics.median(durations)


def interleaved_medians(measure: Callable[[str], float], names: tuple[str, str], rounds: int) -> tuple[float, float]:
    samples = {name: [] for name in names}
    for _ in range(rounds):
        for name in names:
            samples[name].append(measure(name))
    return tuple(statistics.median(samples[name]) for name in names)


def bench_env(env_id: str, args: Args, report: Report) -> None:
    reference = REFERENCES[env_id]
    for obs_mode in args.obs_modes:
        envs = {name: make_env(name, obs_mode) for name in (env_id, reference)}
        steps = args.steps if obs_mode == "state" else max(10, args.steps // 10)
        ours, theirs = interleaved_medians(lambda name: steps_per_second(envs[name], steps), (env_id, reference), args.rounds)
        target = ">= 1.0x"
        report.rows.append(Row(f"{env_id} env.step/s ({obs_mode})", ours, reference, theirs, "steps/s", target))
        if obs_mode == "state":
            ours, theirs = interleaved_medians(
                lambda name: steps_per_second(envs[name], 2 * steps, with_resets=True), (env_id, reference), args.rounds
            )
            report.rows.append(Row(f"{env_id} (env.step + resets)/s ({obs_mode})", ours, reference, theirs, "steps/s", ">= 0.9x"))
            ours, theirs = interleaved_medians(lambda name: reconfigure_seconds(envs[name], args.reconfigures), (env_id, reference), 1)
            report.rows.append(Row(f"{env_id} reconfigure", ours, reference, theirs, "s", "<= 1.0x"))
        for env in envs.values():
            env.close()
    if args.vector_workers and "state" in args.obs_modes:
        envs = {name: make_vector_env(name, args.vector_workers) for name in (env_id, reference)}
        ours, theirs = interleaved_medians(lambda name: vector_steps_per_second(envs[name], args.steps), (env_id, reference), args.rounds)
        report.rows.append(Row(f"{env_id} AsyncVectorEnv x{args.vector_workers} (env.step + resets)/s (state)", ours, reference, theirs, "steps/s", ">= 0.9x"))
        for env in envs.values():
            env.close()


def asset_generators() -> dict[str, Callable[[int], object]]:
    generators = {f"rock ({flavour})": (lambda seed, f=flavour: make_rock(seed, f)) for flavour in ("lunar", "martian")}
    for name in ("moon", "mars", "asteroid"):
        generators[f"terrain ({name})"] = lambda seed, n=name: make_terrain(seed, DOMAINS[n].terrain)
    generators["peg and hole pair (procedural)"] = lambda seed: make_peg_hole_pair(seed)
    arm_base = make_rover().frames["arm_mount"][:3, 3]
    generators["peg and hole pair (as the env draws it: solvability checks, redraws)"] = lambda seed: reachable_peg_hole_pair(seed, DEFAULT_CLEARANCE, arm_base)
    bare_rover = make_rover(cargo_bin=False)  # Multi-Peg-in-Hole's and Solar Panel Assembly's mount
    generators["peg and hole pair at Multi-Peg-in-Hole's outer module (checks with the arm's planning, redraws; cached on disk)"] = lambda seed: _multi_peg_pair(seed, bare_rover)
    generators["debris (procedural)"] = lambda seed: make_debris(seed)
    generators["solar panel set (procedural: 4 sockets, 4 pegs, panel)"] = _solar_panel_set
    generators["solar panel set (as the env draws it: solvability checks, redraws; the arm's planning cached on disk)"] = lambda seed: _reachable_solar_panel_set(seed, bare_rover)
    generators["rover"] = lambda seed: make_rover()
    generators["station"] = lambda seed: make_station()
    generators["sample tube (dataset, cached load)"] = lambda seed: load_dataset_object("sample_tube")
    return generators


def _multi_peg_pair(seed: int, mount) -> tuple:
    from mani_skill.agents.robots.panda.panda import Panda

    positions = module_positions("procedural")
    return reachable_peg_hole_pair(seed, DEFAULT_CLEARANCE, mount.frames["arm_mount"][:3, 3], positions[0], pair_arm_planning(mount, Panda.urdf_path, positions, 0))


def _solar_panel_set(seed: int) -> tuple:
    layout = make_solar_layout(seed)
    return make_socket_base(layout), make_solar_pegs(layout, seed), make_panel(layout)


def _reachable_solar_panel_set(seed: int, mount) -> tuple:
    from mani_skill.agents.robots.panda.panda import Panda

    layout, pegs = reachable_solar_set(seed, DEFAULT_CLEARANCE, mount, Panda.urdf_path)
    return make_socket_base(layout), pegs, make_panel(layout)


def bench_assets(args: Args, report: Report) -> None:
    for name, generate in asset_generators().items():
        start = time.perf_counter()
        for seed in range(args.asset_repeats):
            generate(seed)
        report.assets_ms[name] = 1000 * (time.perf_counter() - start) / args.asset_repeats


def format_report(report: Report) -> str:
    lines = ["| measure | ours | ManiSkill reference | ratio | target |", "|---|---|---|---|---|"]
    for row in report.rows:
        lines.append(
            f"| {row.name} | {row.ours:.3g} {row.unit} | {row.reference_name}: {row.reference:.3g} {row.unit} | {row.ratio:.2f}x | {row.target} |"
        )
    lines += ["", "| asset | ms per asset (with collision parts) |", "|---|---|"]
    lines += [f"| {name} | {ms:.1f} |" for name, ms in report.assets_ms.items()]
    return "\n".join(lines)


def check_env_ids_and_obs_modes(env_ids: Sequence[str], obs_modes: Sequence[str]) -> None:
    """A ``ValueError`` for an env id without a ManiSkill reference or an observation mode the envs reject."""
    for env_id in env_ids:
        if env_id not in REFERENCES:
            raise ValueError(f"no ManiSkill reference for env id {env_id!r}; valid choices: {', '.join(REFERENCES)}")
        for obs_mode in obs_modes:
            task_class(env_id).check_task_kwargs(obs_mode=obs_mode)


def check_args(args: Args) -> None:
    """A ``ValueError`` naming the first bad input: an env id without a ManiSkill reference, an observation mode
    the envs reject, a count below 1."""
    check_env_ids_and_obs_modes(args.env_ids, args.obs_modes)
    for name, value in (("--steps", args.steps), ("--rounds", args.rounds), ("--reconfigures", args.reconfigures), ("--asset-repeats", args.asset_repeats)):
        check_at_least(name, value, 1)
    check_at_least("--vector-workers", args.vector_workers, 0)


def main(args: Args) -> Report:
    with checking_inputs():
        check_args(args)
    report = Report()
    for env_id in args.env_ids:
        bench_env(env_id, args, report)
    bench_assets(args, report)
    print(format_report(report))
    if args.json_path is not None:
        payload = {"rows": [asdict(r) | {"ratio": r.ratio} for r in report.rows], "assets_ms": report.assets_ms}
        args.json_path.write_text(json.dumps(payload, indent=1))
    return report


def cli(argv: Optional[Sequence[str]] = None) -> None:
    """``mani-skill-space bench ARGS`` (and ``python -m mani_skill_space.bench ARGS``)."""
    run_cli("bench", tyro_parser(Args, "bench", __doc__), main, argv)


if __name__ == "__main__":
    cli()
