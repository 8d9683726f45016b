"""ManiSkill's trajectory replay tool with mani-skill-space's envs registered.

    mani-skill-space replay --traj-path demos/SampleCollection-v1/motionplanning/<name>.h5 -c pd_ee_delta_pose -o state --save-traj
    python -m mani_skill_space.replay --traj-path demos/SampleCollection-v1/motionplanning/<name>.h5 \\
        -c pd_ee_delta_pose -o state --save-traj

Same arguments as ``python -m mani_skill.trajectory.replay_trajectory`` (``--help`` lists them). That tool
calls ``gym.make`` on the recorded env id without importing third-party task packs; importing this module
first registers ours, here and in the tool's worker processes (which re-import this module). Like ManiSkill's
tool, it starts its worker processes with the ``spawn`` method.

The trajectory (its ``.h5`` file and the ``.json`` beside it), the recorded env id and, for our envs, the recorded
env kwargs with the target control and observation modes are checked before the replay starts; a bad one is one
line on stderr and exit status 2 (``--debug`` shows the traceback; see ``mani_skill_space.cli_support``).
"""

from __future__ import annotations

import json
import multiprocessing as mp
from pathlib import Path
from typing import Optional, Sequence

from mani_skill.trajectory import replay_trajectory
from mani_skill.utils.registration import REGISTERED_ENVS

import mani_skill_space  # noqa: F401  (registers the envs)
from mani_skill_space.cli_support import DEBUG_HELP, check_at_least, checking_inputs, run_cli
from mani_skill_space.envs import TASKS
from mani_skill_space.suites import check_env_kwargs


def check_args(args: replay_trajectory.Args) -> None:
    """A ``ValueError`` or ``OSError`` naming the first bad input: a missing trajectory or metadata file, an env id
    that neither we nor ManiSkill register, recorded env kwargs or a target mode that our env rejects."""
    path = Path(args.traj_path)
    if path.suffix != ".h5":
        raise ValueError(f"--traj-path must name a trajectory's .h5 file (its .json lies beside it), got {path}")
    if not path.is_file():
        raise FileNotFoundError(f"no trajectory file {path}")
    metadata_path = path.with_suffix(".json")
    try:
        metadata = json.loads(metadata_path.read_text())
        env_info = metadata["env_info"]
        env_id, env_kwargs = env_info["env_id"], dict(env_info.get("env_kwargs", {}))
    except FileNotFoundError:
        raise FileNotFoundError(f"no metadata file {metadata_path} beside the trajectory {path}") from None
    except (json.JSONDecodeError, KeyError, TypeError) as error:
        raise ValueError(f"{metadata_path} is not a ManiSkill trajectory's metadata (env_info.env_id and env_kwargs): {error!r}") from None
    if env_id not in REGISTERED_ENVS:
        raise ValueError(f"{path} was recorded on {env_id!r}, which neither mani-skill-space nor ManiSkill registers")
    check_at_least("--count", args.count, 1)
    if env_id in TASKS:
        for key, value in (("control_mode", args.target_control_mode), ("obs_mode", args.obs_mode), ("reward_mode", args.reward_mode)):
            if value is not None:
                env_kwargs[key] = value
        check_env_kwargs(TASKS[env_id], env_kwargs)


def _replay_in_worker(job):
    """ManiSkill's per-process replay, reached through this module so that a spawned worker, which unpickles the
    function by its module's name, imports mani_skill_space (registering our envs) before it makes an env."""
    return replay_trajectory._main(*job)


def main(args: replay_trajectory.Args) -> None:
    with checking_inputs():
        check_args(args)
    # ManiSkill's pool maps its module-level ``_main_helper``; swapping it in is how workers learn our envs
    replay_trajectory._main_helper = _replay_in_worker
    replay_trajectory.main(args)


def parse(arguments: list[str]) -> replay_trajectory.Args:
    """ManiSkill's replay arguments; ``--help`` also lists ``--debug``."""
    if any(a in ("-h", "--help") for a in arguments):
        print(f"mani-skill-space replay: ManiSkill's replay_trajectory with mani-skill-space's envs registered.\n{DEBUG_HELP}\n")
    return replay_trajectory.parse_args(arguments)


def cli(argv: Optional[Sequence[str]] = None) -> None:
    """``mani-skill-space replay ARGS`` (and ``python -m mani_skill_space.replay ARGS``)."""
    mp.set_start_method("spawn", force=True)
    run_cli("replay", parse, main, argv)


if __name__ == "__main__":
    cli()
