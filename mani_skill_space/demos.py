"""Generate motion-planning demonstrations with the tasks' oracles, recorded in ManiSkill's trajectory format.

    mani-skill-space demos -e SampleCollection-v1 -n 100 --env-kwargs '{"domain": "mars"}'
    python -m mani_skill_space.demos -e SampleCollection-v1 -n 100 --env-kwargs '{"domain": "mars"}'

The flags mirror ManiSkill's ``mani_skill.examples.motionplanning.panda.run``, plus ``--env-kwargs`` (a JSON
object: domain, asset_source, ...) and ``--seed-start``. Output: ``<record-dir>/<env-id>/motionplanning/
<traj-name>.h5`` and ``.json``, written by ManiSkill's ``RecordEpisode`` (actions in ``--control-mode``: ``pd_joint_pos``
by default, or ``pd_ee_delta_pose``, in which the oracle acts directly; env states, per-step success; the JSON
carries the env kwargs and each episode's seed). Convert them to another control mode or observation mode with
``python -m mani_skill_space.replay`` (ManiSkill's replay tool with our envs registered), e.g.
``-c pd_ee_delta_pose -o state --save-traj``.

With several processes, process i takes seeds seed_start + i, seed_start + i + procs, ... (disjoint), and
the per-process files are merged with ManiSkill's ``merge_trajectories``.

The env id, ``--env-kwargs`` (names and values, as the env checks them) and the counts are checked before any
worker starts; a bad one is one line on stderr and exit status 2 (``--debug`` shows the traceback; see
``mani_skill_space.cli_support``).
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Annotated, Optional, Sequence

import gymnasium as gym
import numpy as np
import tyro
from mani_skill.trajectory.merge_trajectory import merge_trajectories
from mani_skill.utils.wrappers.record import RecordEpisode
from tqdm import tqdm

from mani_skill_space.cli_support import check_at_least, checking_inputs, parse_json_object, run_cli, tyro_parser
from mani_skill_space.envs import task_class
from mani_skill_space.kwarg_checks import checked_number
from mani_skill_space.oracles import ORACLE_CONTROL_MODES, ORACLES, oracle_for
from mani_skill_space.rollout import run_episode
from mani_skill_space.suites import check_env_kwargs

SET_BY_THE_GENERATOR = (
    "obs_mode",
    "control_mode",
    "reward_mode",
    "render_mode",
    "sim_backend",
    "sensor_configs",
    "human_render_camera_configs",
    "viewer_camera_configs",
)
"""Env kwargs the generator sets itself (from its flags, or the oracle's control mode): not for ``--env-kwargs``."""


@dataclass
class Args:
    env_id: Annotated[str, tyro.conf.arg(aliases=["-e"])] = "SampleCollection-v1"
    """Env to solve; oracles exist for the ids in ``mani_skill_space.oracles.ORACLES``."""
    control_mode: Annotated[str, tyro.conf.arg(aliases=["-c"])] = "pd_joint_pos"
    """Control mode the oracle acts and is recorded in: pd_joint_pos (its joint targets; convert them with replay)
    or pd_ee_delta_pose (the default control mode, recorded natively: no conversion)."""
    obs_mode: Annotated[str, tyro.conf.arg(aliases=["-o"])] = "none"
    """Observations to store; usually none (replay the demos later to get any observation mode)."""
    num_traj: Annotated[int, tyro.conf.arg(aliases=["-n"])] = 10
    only_count_success: bool = False
    """Keep going until num_traj demos succeed; save only the successful ones."""
    reward_mode: Optional[str] = None
    record_rewards: bool = False
    """Store every step's reward (of ``--reward-mode``, which must then be given) in the file, as ManiSkill's replay
    ``--record-rewards`` does: what RLPD on a dense reward learns from (``baselines/sac.py --demos``)."""
    sim_backend: Annotated[str, tyro.conf.arg(aliases=["-b"])] = "auto"
    render_mode: str = "rgb_array"
    vis: bool = False
    """Show the solution live in SAPIEN's viewer (needs a display)."""
    save_video: bool = False
    traj_name: Optional[str] = None
    """Name of the .h5/.json files (default: a timestamp)."""
    shader: str = "default"
    record_dir: str = "demos"
    num_procs: Annotated[int, tyro.conf.arg(aliases=["-j"])] = os.cpu_count() or 1
    env_kwargs: str = "{}"
    """JSON object of env kwargs, e.g. '{"domain": "moon", "asset_source": "dataset"}'."""
    seed_start: int = 0
    action_noise: float = 0.0
    """DART-style demonstrations (Laskey et al. 2017): Gaussian noise of this standard deviation is added to the
    arm's part of every action the env executes, while the file records the oracle's own action, in the control
    mode's units: normalised for ``pd_ee_delta_pose`` (0.03 moves the TCP about 3 mm; the closed-loop oracle
    corrects it at its next step), radians of joint target for ``pd_joint_pos`` (0.002 moves the TCP about 2 mm;
    while the oracle follows a planned path, its next absolute target takes the arm back to it, and each new motion
    is planned from where the arm is). The demonstrations then show how to come back from states a little off the
    oracle's path, the states an imitation learner's own errors lead to. The file's env states are the executed ones
    (replay them with ``--use-env-states``, not by their actions)."""


@dataclass(frozen=True)
class Outcome:
    path: str
    attempts: int
    successes: int
    saved: int


def generate(args: Args, proc_id: int = 0) -> Outcome:
    import mani_skill_space  # noqa: F401  (registers the envs in a spawned worker)

    oracle = oracle_for(args.env_id, args.control_mode)
    kwargs = json.loads(args.env_kwargs)
    env = gym.make(
        args.env_id,
        obs_mode=args.obs_mode,
        control_mode=oracle.control_mode,
        render_mode=args.render_mode,
        reward_mode=args.reward_mode,
        sim_backend=args.sim_backend,
        sensor_configs=dict(shader_pack=args.shader),
        human_render_camera_configs=dict(shader_pack=args.shader),
        viewer_camera_configs=dict(shader_pack=args.shader),
        **kwargs,
    )
    if args.action_noise > 0:
        env = ArmActionNoise(env, args.action_noise)
    name = args.traj_name if args.num_procs == 1 else f"{args.traj_name}.{proc_id}"
    env = RecordEpisode(
        env,
        output_dir=str(Path(args.record_dir) / args.env_id / "motionplanning"),
        trajectory_name=name,
        save_video=args.save_video,
        source_type="motionplanning",
        source_desc="mani-skill-space motion-planning oracle (mani_skill_space.oracles)",
        video_fps=int(env.unwrapped.control_freq),
        record_reward=args.record_rewards,
        save_on_reset=False,
    )
    path = env._h5_file.filename
    render = env.unwrapped.render_human if args.vis else None
    seed, attempts, successes, saved = args.seed_start + proc_id, 0, 0, 0
    with tqdm(total=args.num_traj, desc=f"proc {proc_id}", position=proc_id) as progress:
        while saved < args.num_traj:
            result = run_episode(env, oracle, seed, stop_when_done=True, on_step=render)
            attempts += 1
            successes += result.success_at_end
            keep = result.success_at_end or not args.only_count_success
            env.flush_trajectory(save=keep)
            if args.save_video:
                env.flush_video(save=keep)
            saved += keep
            progress.update(keep)
            progress.set_postfix(success_rate=f"{successes / attempts:.2f}")
            seed += args.num_procs
    env.close()
    return Outcome(path, attempts, successes, saved)


class ArmActionNoise(gym.Wrapper):
    """Adds Gaussian noise of ``std`` to the arm's dimensions (all but the gripper's last) of every action, clipped to
    the action space; the noise is drawn from the episode's seed, so a demonstration is reproducible."""

    def __init__(self, env: gym.Env, std: float):
        super().__init__(env)
        self.std = std
        self.rng = np.random.default_rng()

    def reset(self, *, seed=None, options=None):
        self.rng = np.random.default_rng(seed)
        return super().reset(seed=seed, options=options)

    def step(self, action):
        action = np.array(action, dtype=np.float32, copy=True)
        action[..., :-1] += self.std * self.rng.standard_normal(action[..., :-1].shape)
        return super().step(np.clip(action, self.action_space.low, self.action_space.high))


def check_args(args: Args) -> None:
    """A ``ValueError`` naming the first bad input: an env id without an oracle, ``--env-kwargs`` that is not a
    JSON object or that the env rejects (names and values), a count below 1."""
    if args.env_id not in ORACLES:
        raise ValueError(f"no oracle for env id {args.env_id!r}; valid choices: {', '.join(ORACLES)}")
    if args.control_mode not in ORACLE_CONTROL_MODES:
        raise ValueError(f"unknown --control-mode {args.control_mode!r}; valid choices: {', '.join(ORACLE_CONTROL_MODES)}")
    check_at_least("--num-traj", args.num_traj, 1)
    check_at_least("--num-procs", args.num_procs, 1)
    check_at_least("--seed-start", args.seed_start, 0)
    checked_number("--action-noise", args.action_noise, 0.0, 1.0, meaning="the control mode's action units: normalised, or radians for pd_joint_pos")
    if args.record_rewards and args.reward_mode in (None, "none"):
        raise ValueError("--record-rewards needs --reward-mode (e.g. normalized_dense; it names the reward the file stores)")
    kwargs = parse_json_object(args.env_kwargs, "--env-kwargs")
    for key in kwargs:
        if key in SET_BY_THE_GENERATOR:
            raise ValueError(f"--env-kwargs cannot set {key!r}: the demo generator sets it (from its own flags or the oracle)")
    check_env_kwargs(task_class(args.env_id), dict(kwargs, obs_mode=args.obs_mode, reward_mode=args.reward_mode))


def main(args: Args) -> Outcome:
    with checking_inputs():
        check_args(args)
    start = time.perf_counter()
    args = replace(args, traj_name=args.traj_name or time.strftime("%Y%m%d_%H%M%S"))
    procs = max(1, min(args.num_procs, args.num_traj))
    if procs == 1:
        outcome = generate(replace(args, num_procs=1))
    else:
        shares = [args.num_traj // procs + (i < args.num_traj % procs) for i in range(procs)]
        with get_context("spawn").Pool(procs) as pool:
            parts = pool.starmap(generate, [(replace(args, num_traj=n, num_procs=procs), i) for i, n in enumerate(shares)])
        merged = parts[0].path[: -len(".0.h5")] + ".h5"
        merge_trajectories(merged, [p.path for p in parts])
        for part in parts:
            os.remove(part.path)
            os.remove(part.path.replace(".h5", ".json"))
        outcome = Outcome(merged, sum(p.attempts for p in parts), sum(p.successes for p in parts), sum(p.saved for p in parts))
    minutes = (time.perf_counter() - start) / 60
    print(
        f"{outcome.saved} trajectories saved to {outcome.path} ({outcome.successes}/{outcome.attempts} successful, "
        f"{outcome.saved / minutes:.1f} trajectories per minute with {procs} process(es))"
    )
    return outcome


def cli(argv: Optional[Sequence[str]] = None) -> None:
    """``mani-skill-space demos ARGS`` (and ``python -m mani_skill_space.demos ARGS``)."""
    run_cli("demos", tyro_parser(Args, "demos", __doc__), main, argv)


if __name__ == "__main__":
    cli()
