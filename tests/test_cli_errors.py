"""A user's mistake on any command line is one clear line on stderr and exit status 2, never a traceback; ``--debug``
shows the traceback, and a genuine bug still shows one. Each case runs the tool as a user would, in a subprocess."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from mani_skill_space.cli_support import PROG, USER_ERROR_EXIT_STATUS


def _run(tmp_path, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, cwd=tmp_path, timeout=300, env=env)


def _assert_one_line_error(result: subprocess.CompletedProcess, tool: str, message: str) -> None:
    assert result.returncode == USER_ERROR_EXIT_STATUS, result.stderr
    assert "Traceback" not in result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    errors = [line for line in lines if line.startswith(f"{PROG} {tool}: error: ")]
    assert len(errors) == 1, result.stderr
    assert message in errors[0]
    assert errors[0] == lines[-1], "the error is the last thing on stderr"


def _suite(tmp_path, kwargs: str) -> str:
    path = tmp_path / "bad.toml"
    path.write_text(f'name = "bad"\n\n[[configurations]]\nenv_id = "SolarPanelAssembly-v1"\nkwargs = {{ {kwargs} }}\n')
    return str(path)


def _trajectory(tmp_path, env_id: str, env_kwargs: dict) -> str:
    (tmp_path / "demo.h5").write_bytes(b"")
    (tmp_path / "demo.json").write_text(json.dumps(dict(env_info=dict(env_id=env_id, env_kwargs=env_kwargs), episodes=[])))
    return str(tmp_path / "demo.h5")


def _stale_checkpoint(tmp_path) -> list[str]:
    """A Sample Collection checkpoint that takes 5 state observations (trained on another version of the env), and a
    one-episode suite of that env."""
    from mani_skill_space.learning import BehaviourCloningPolicy, save_checkpoint

    kwargs = dict(state_dim=5, action_dim=7, hidden=8, depth=1)
    path = save_checkpoint(tmp_path / "stale.pt", "bc", BehaviourCloningPolicy(**kwargs), kwargs, "SampleCollection-v1", {"domain": "mars"}, "state", "pd_ee_delta_pose")
    suite = tmp_path / "one.toml"
    suite.write_text('name = "one"\nepisodes = 1\n\n[[configurations]]\nenv_id = "SampleCollection-v1"\nkwargs = { domain = "mars", asset_source = "dataset" }\n')
    return ["--suite", str(suite), "--policy", f"checkpoint:{path}", "--num-workers", "1"]


CASES = [
    ("eval", lambda t: ["--suite", "no_such_suite"], "unknown suite 'no_such_suite'; shipped suites: "),
    ("eval", lambda t: ["--suite", str(t / "missing.toml")], "missing.toml: no such suite file"),
    ("eval", lambda t: ["--suite", _suite(t, "clearance = 0.02")], "bad.toml:5: clearance must be positive and at most 0.001964 m"),
    ("eval", lambda t: ["--suite", _suite(t, 'domain = ""')], "bad.toml:5: unknown domain ''; valid choices: moon, mars, orbit, earth"),
    ("eval", lambda t: ["--suite", "smoke", "--policy", "dreamer"], "Unknown policy 'dreamer'; valid choices: random, zero, oracle"),
    ("eval", lambda t: ["--suite", "smoke", "--policy", "no_such_module:make"], "cannot import module 'no_such_module'"),
    ("eval", lambda t: ["--suite", "smoke", "--policy", "checkpoint:missing.pt"], "missing.pt"),
    ("eval", _stale_checkpoint, "stale.pt takes 5 state observations and this version of SampleCollection-v1 gives "),
    ("eval", lambda t: ["--suite", "smoke", "--num-workers", "0"], "--num-workers must be at least 1, got 0"),
    ("eval", lambda t: ["--policy", "zero"], "give either --suite (a benchmark suite) or --protocol (a generalisation protocol)"),
    ("eval", lambda t: ["--protocol", "no_such_protocol"], "unknown protocol 'no_such_protocol'; shipped protocols: "),
    ("demos", lambda t: ["-e", "NoSuchTask-v1"], "no oracle for env id 'NoSuchTask-v1'; valid choices: SampleCollection-v1"),
    ("demos", lambda t: ["--env-kwargs", "{domain: moon}"], "--env-kwargs is not valid JSON"),
    ("demos", lambda t: ["--env-kwargs", "[1, 2]"], "--env-kwargs must be a JSON object"),
    ("demos", lambda t: ["--env-kwargs", '{"domian": "moon"}'], "SampleCollectionEnv takes no kwarg 'domian'"),
    ("demos", lambda t: ["--env-kwargs", '{"robot_init_qpos_noise": NaN}'], "robot_init_qpos_noise must be a finite number"),
    ("demos", lambda t: ["-e", "DebrisCapture-v1", "--env-kwargs", '{"difficulty": 100}'], "difficulty must be a finite number >= 0 and <= 2"),
    ("demos", lambda t: ["--env-kwargs", '{"control_mode": "pd_ee_delta_pose"}'], "--env-kwargs cannot set 'control_mode'"),
    ("demos", lambda t: ["-c", "pd_ee_pose"], "unknown --control-mode 'pd_ee_pose'; valid choices: pd_joint_pos, pd_ee_delta_pose"),
    ("demos", lambda t: ["-c", "pd_ee_delta_pose", "--action-noise", "nan"], "--action-noise must be a finite number >= 0 and <= 1 (the control mode's action units: normalised, or radians for pd_joint_pos), got nan"),
    ("demos", lambda t: ["--record-rewards"], "--record-rewards needs --reward-mode"),
    ("replay", lambda t: ["--traj-path", str(t / "missing.h5")], "no trajectory file"),
    ("replay", lambda t: ["--traj-path", _trajectory(t, "NoSuchTask-v1", {})], "'NoSuchTask-v1', which neither mani-skill-space nor ManiSkill registers"),
    ("replay", lambda t: ["--traj-path", _trajectory(t, "PegInHoleAssembly-v1", {"domain": "moon"}), "-c", "pd_magic"], "unknown control_mode 'pd_magic'"),
    ("bench", lambda t: ["--env-ids", "NoSuchTask-v1"], "no ManiSkill reference for env id 'NoSuchTask-v1'"),
    ("bench", lambda t: ["--obs-modes", "rgbdd"], "unknown obs_mode 'rgbdd'"),
    ("showcase", lambda t: ["--env-ids", "NoSuchTask-v1"], "Unknown env id 'NoSuchTask-v1'; valid choices: SampleCollection-v1"),
]


@pytest.mark.parametrize("tool, arguments, message", CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def test_a_user_error_is_one_line_and_exit_status_2(tmp_path, tool, arguments, message):
    _assert_one_line_error(_run(tmp_path, f"mani_skill_space.{tool}", *arguments(tmp_path)), tool, message)


def test_the_mani_skill_space_command_reports_the_same_way(tmp_path):
    _assert_one_line_error(_run(tmp_path, "mani_skill_space", "demos", "--env-kwargs", "[1, 2]"), "demos", "--env-kwargs must be a JSON object")


def test_debug_shows_the_traceback_of_a_user_error(tmp_path):
    result = _run(tmp_path, "mani_skill_space.eval", "--suite", "no_such_suite", "--debug")
    assert result.returncode != 0
    assert "Traceback" in result.stderr and "UserError: unknown suite 'no_such_suite'" in result.stderr


def test_a_bug_is_not_dressed_up_as_a_user_error(tmp_path):
    """A policy factory that crashes is a bug in that code, not a bad argument: its traceback is shown."""
    (tmp_path / "crashing_policy.py").write_text(textwrap.dedent("""\
        def make():
            raise RuntimeError("the policy's own bug")
    """))
    result = _run(tmp_path, "mani_skill_space.eval", "--suite", "smoke", "--policy", "crashing_policy:make", env=_with_pythonpath(tmp_path))
    assert result.returncode == 1
    assert "Traceback" in result.stderr and "RuntimeError: the policy's own bug" in result.stderr
    assert f"{PROG} eval: error:" not in result.stderr


def _with_pythonpath(path) -> dict:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(path), os.environ.get("PYTHONPATH", "")])}
