"""ManiSkill's state contract on our envs: restoring ``get_state_dict()`` (or the flat ``get_state()``) restores the
observation. Adapted from ManiSkill's ``tests/test_envs.py::test_raw_sim_states`` to mani-skill 3.0.1 on the CPU
(one env; ManiSkill's version runs 16 on the GPU). PickCube-v1 is the control: ManiSkill's own task passes it.
Demonstration replay with ``--use-env-states`` and reset-to-state curricula rely on it."""

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import h5py
import numpy as np
import pytest
import torch
from mani_skill.trajectory.utils import dict_to_list_of_dicts
from mani_skill.utils import common

import mani_skill_space
from mani_skill_space import demos

ENV_IDS = ("PickCube-v1", *mani_skill_space.ENV_IDS)


def assert_obs_equal(obs1, obs2):
    """ManiSkill's ``tests/utils.py::assert_obs_equal`` for float and integer observations."""
    obs1, obs2 = common.flatten_dict_keys(common.to_numpy(obs1)), common.flatten_dict_keys(common.to_numpy(obs2))
    assert obs1.keys() == obs2.keys()
    for key, value in obs1.items():
        if np.issubdtype(value.dtype, np.integer):
            np.testing.assert_equal(value, obs2[key], err_msg=key)
        else:
            np.testing.assert_allclose(value, obs2[key], err_msg=key, atol=1e-4)


def _make(env_id):
    env = gym.make(env_id, obs_mode="state_dict", render_backend="none")
    env.action_space.seed(0)
    return env


def _steps(env, count):
    for _ in range(count):
        env.step(env.action_space.sample())


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_raw_sim_states(env_id):
    env = _make(env_id)
    base_env = env.unwrapped
    obs1, _ = env.reset(seed=0)
    state_dict = base_env.get_state_dict()
    assert isinstance(state_dict, dict) and {"actors", "articulations"} <= state_dict.keys()
    _steps(env, 5)
    base_env.set_state_dict(state_dict)
    assert_obs_equal(obs1, base_env.get_obs())
    _steps(env, 5)
    state = base_env.get_state()
    obs1 = base_env.get_obs()
    assert state.shape == (1, common.flatten_state_dict(base_env.get_state_dict(), use_torch=True).shape[1])
    _steps(env, 5)
    base_env.set_state(state)
    assert_obs_equal(obs1, base_env.get_obs())
    env.close()


@pytest.mark.parametrize("env_id", mani_skill_space.ENV_IDS)
def test_the_state_carries_the_elapsed_steps_and_the_wrist_wrench(env_id):
    """The observation entries the simulation state cannot restore: the remaining time comes from the elapsed steps
    (also what the time limit counts) and the wrist wrench from the last physics step's joint forces."""
    env = _make(env_id)
    base_env = env.unwrapped
    env.reset(seed=1)
    _steps(env, 7)
    state_dict = base_env.get_state_dict()
    assert state_dict["task"]["elapsed_steps"].tolist() == [[7.0]]
    wrench = base_env.get_obs()["extra"]["wrist_wrench"].clone()
    assert torch.equal(state_dict["task"]["wrist_wrench"], wrench)
    assert wrench.abs().max() > 0, "a held arm under its own weight or in contact transmits some wrench"
    _steps(env, 3)
    base_env.set_state_dict(state_dict)
    assert base_env.elapsed_steps.tolist() == [7]
    assert torch.equal(base_env.get_obs()["extra"]["wrist_wrench"], wrench)
    env.close()


@pytest.mark.parametrize("env_id", mani_skill_space.ENV_IDS)
def test_a_bare_simulation_state_still_restores_the_scene(env_id):
    """States recorded before the task entry existed (or by tools that keep only the simulation) still load: the
    scene is restored, the elapsed steps and the wrench reading are left as they are."""
    env = _make(env_id)
    base_env = env.unwrapped
    env.reset(seed=2)
    state_dict = base_env.get_state_dict()
    bare = {key: state_dict[key] for key in ("actors", "articulations")}
    _steps(env, 3)
    base_env.set_state_dict(bare)
    assert base_env.elapsed_steps.tolist() == [3]
    restored = base_env.get_state_dict()
    for group in ("actors", "articulations"):
        for name, value in bare[group].items():
            torch.testing.assert_close(restored[group][name], value, atol=1e-5, rtol=0)
    env.close()


def test_a_reset_reads_no_wrench_of_the_previous_episode():
    """Without a reconfigure the scene lives on between episodes: the first observation of an episode reads no
    wrench, whatever the previous episode's last physics step measured."""
    env = gym.make("PegInHoleAssembly-v1", obs_mode="state_dict", render_backend="none", reconfiguration_freq=0)
    env.action_space.seed(0)
    first, _ = env.reset(seed=3)
    _steps(env, 5)
    assert env.unwrapped.get_obs()["extra"]["wrist_wrench"].abs().max() > 0
    again, _ = env.reset(seed=3)
    assert first["extra"]["wrist_wrench"].abs().max() == 0
    assert_obs_equal(first, again)
    env.close()


def test_a_demonstration_replays_by_env_states(tmp_path):
    """ManiSkill's replay with ``--use-env-states`` sets every recorded state (read back from the trajectory file,
    one env's state per step) and succeeds where the demonstration did; each recorded state, task entries included,
    is what the env then holds."""
    args = demos.Args(env_id="PegInHoleAssembly-v1", num_traj=1, num_procs=1, seed_start=0, only_count_success=True, record_dir=str(tmp_path), traj_name="demo")
    path = demos.main(args).path
    command = [sys.executable, "-m", "mani_skill_space.replay", "--traj-path", path, "--use-env-states", "-o", "state", "--save-traj"]
    result = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "Replayed 1 episodes, 1/1" in result.stdout

    meta = json.loads(Path(path).with_suffix(".json").read_text())
    kwargs = {k: v for k, v in meta["env_info"]["env_kwargs"].items() if k != "render_mode"}
    env = gym.make(meta["env_info"]["env_id"], **kwargs)  # rendering on, as recorded: the skydome is in the state
    env.reset(**meta["episodes"][0]["reset_kwargs"])
    with h5py.File(path) as trajectories:
        states = dict_to_list_of_dicts(trajectories["traj_0"]["env_states"])
    assert states[-1]["task"]["elapsed_steps"][0] == len(states) - 1
    for t in (0, len(states) // 2, len(states) - 1):
        env.unwrapped.set_state_dict(states[t])
        held = common.to_numpy(env.unwrapped.get_state_dict())
        for name, value in states[t]["task"].items():
            np.testing.assert_array_equal(held["task"][name][0], value, err_msg=name)
        np.testing.assert_allclose(held["actors"]["peg"][0], states[t]["actors"]["peg"], atol=1e-5)
    env.close()
