"""The ``mani-skill-space`` command dispatches to each tool's ``cli`` and explains itself when misused."""

import importlib
import subprocess
import sys

import pytest

from mani_skill_space import cli


@pytest.mark.parametrize("tool", list(cli.TOOLS))
def test_every_tool_module_has_the_cli_entry_the_command_calls(tool):
    assert callable(importlib.import_module(f"mani_skill_space.{tool}").cli)


@pytest.mark.parametrize("argv, problem", [([], "no command given"), (["evaluate"], "unknown command 'evaluate'")])
def test_a_missing_or_unknown_command_prints_the_usage_and_exits_2(capsys, argv, problem):
    with pytest.raises(SystemExit) as exit:
        cli.main(argv)
    assert exit.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: mani-skill-space {eval,demos,replay,bench,showcase}")
    assert err.splitlines()[-1] == f"mani-skill-space: error: {problem}; valid choices: eval, demos, replay, bench, showcase"


def test_help_lists_every_command_without_importing_the_tools():
    script = "import sys; from mani_skill_space.cli import main; main(['--help']); print(sorted(m for m in sys.modules if m.startswith('mani_skill_space.') and m.split('.')[1] in ('eval', 'demos', 'replay', 'bench', 'showcase')))"
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    *usage, imported = result.stdout.splitlines()
    assert imported == "[]"
    assert all(any(line.split()[:1] == [tool] for line in usage) for tool in cli.TOOLS)


def test_the_command_passes_the_rest_of_the_arguments_to_the_tool(capsys):
    with pytest.raises(SystemExit) as exit:
        cli.main(["eval", "--help"])
    assert exit.value.code == 0
    assert "--suite" in capsys.readouterr().out


def test_python_dash_m_mani_skill_space_is_the_command():
    result = subprocess.run([sys.executable, "-m", "mani_skill_space", "bogus"], capture_output=True, text=True)
    assert result.returncode == 2
    assert "unknown command 'bogus'" in result.stderr
