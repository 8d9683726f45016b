"""The ``mani-skill-space`` command: every command-line tool of the package behind one name.

    mani-skill-space eval --suite smoke --policy oracle random
    mani-skill-space demos -e PegInHoleAssembly-v1 -n 10
    mani-skill-space replay --traj-path demos/PegInHoleAssembly-v1/motionplanning/<name>.h5 -c pd_ee_delta_pose -o state --save-traj
    mani-skill-space bench
    mani-skill-space showcase

``mani-skill-space TOOL ARGS`` runs ``python -m mani_skill_space.TOOL ARGS`` (so does
``python -m mani_skill_space TOOL ARGS``); ``mani-skill-space TOOL --help`` lists the tool's arguments. A tool's
module is imported only when it runs.
"""

from __future__ import annotations

import importlib
import sys
from typing import Optional, Sequence

PROG = "mani-skill-space"

TOOLS = {
    "eval": "evaluate policies on a benchmark suite (a shipped suite name such as smoke, or a .toml file) or a generalisation protocol (--protocol levels)",
    "demos": "record oracle demonstrations (ManiSkill trajectory format)",
    "replay": "replay or convert demonstrations (ManiSkill's replay_trajectory with our envs registered)",
    "bench": "measure env speed against ManiSkill's own tasks",
    "showcase": "render every env in each domain and asset source (picture grid and videos)",
}
"""Subcommands: the module ``mani_skill_space.<name>`` of each provides ``cli(argv)``."""

HELP_FLAGS = ("-h", "--help")


def usage() -> str:
    width = max(map(len, TOOLS))
    lines = [f"usage: {PROG} {{{','.join(TOOLS)}}} [ARGS ...]", "", "commands:"]
    lines += [f"  {name.ljust(width)}  {summary}" for name, summary in TOOLS.items()]
    lines += ["", f"`{PROG} COMMAND --help` lists the arguments of a command."]
    return "\n".join(lines)


def main(argv: Optional[Sequence[str]] = None) -> None:
    """Run ``mani-skill-space COMMAND ARGS``: dispatch to ``mani_skill_space.COMMAND.cli(ARGS)``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in HELP_FLAGS:
        print(usage())
        return
    if not argv or argv[0] not in TOOLS:
        print(usage(), file=sys.stderr)
        problem = f"unknown command {argv[0]!r}" if argv else "no command given"
        print(f"{PROG}: error: {problem}; valid choices: {', '.join(TOOLS)}", file=sys.stderr)
        raise SystemExit(2)
    command, rest = argv[0], argv[1:]
    importlib.import_module(f"mani_skill_space.{command}").cli(rest)
