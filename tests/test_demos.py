"""Demonstrations: recorded in ManiSkill's format, converted by ManiSkill's replay tool, loaded by its dataset."""

import json
import subprocess
import sys

import gymnasium as gym
import h5py
import numpy as np
import pytest
from mani_skill.trajectory.dataset import ManiSkillTrajectoryDataset
from mani_skill.trajectory.utils import dict_to_list_of_dicts

from mani_skill_space import demos


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    record_dir = tmp_path_factory.mktemp("demos")
    args = demos.Args(num_traj=3, num_procs=2, record_dir=str(record_dir), traj_name="demo", env_kwargs='{"domain": "moon", "asset_source": "dataset"}', seed_start=20)
    outcome = demos.main(args)
    return outcome


def test_demos_are_recorded_with_env_kwargs_seeds_and_success(recorded):
    assert recorded.saved == 3 and recorded.path.endswith("SampleCollection-v1/motionplanning/demo.h5")
    meta = json.loads(open(recorded.path.replace(".h5", ".json")).read())
    assert meta["env_info"]["env_kwargs"]["domain"] == "moon"
    assert meta["env_info"]["env_kwargs"]["control_mode"] == "pd_joint_pos"
    assert sorted(e["reset_kwargs"]["seed"] for e in meta["episodes"]) == [20, 21, 22]  # disjoint per process
    assert all(e["success"] for e in meta["episodes"])
    with h5py.File(recorded.path) as trajectories:
        assert len(trajectories) == 3
        for trajectory in trajectories.values():
            assert trajectory["actions"].shape[1] == 8 and trajectory["success"][-1]


def test_a_recorded_demo_replays_to_the_same_final_state(recorded):
    meta = json.loads(open(recorded.path.replace(".h5", ".json")).read())
    episode = meta["episodes"][0]
    kwargs = {k: v for k, v in meta["env_info"]["env_kwargs"].items() if k not in ("render_mode",)}
    env = gym.make(meta["env_info"]["env_id"], **kwargs, render_backend="none")
    env.reset(**episode["reset_kwargs"])
    with h5py.File(recorded.path) as trajectories:
        trajectory = trajectories[f"traj_{episode['episode_id']}"]
        for action in trajectory["actions"][:]:
            env.step(action)
        states = dict_to_list_of_dicts(trajectory["env_states"])
    final = env.unwrapped.get_state_dict()
    np.testing.assert_allclose(final["actors"]["sample"][0], states[-1]["actors"]["sample"], atol=1e-5)
    np.testing.assert_allclose(final["articulations"]["panda"][0], states[-1]["articulations"]["panda"], atol=1e-5)
    env.close()


def test_maniskill_replay_converts_demos_to_ee_delta_pose_and_the_dataset_loads_them(recorded):
    # two worker processes: each must know our env ids
    command = [sys.executable, "-m", "mani_skill_space.replay", "--traj-path", recorded.path, "-c", "pd_ee_delta_pose", "-o", "state", "--save-traj", "-n", "2"]
    result = subprocess.run(command, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-2000:]
    assert "Replayed 3 episodes, 3/3" in result.stdout
    converted = recorded.path.replace(".h5", ".state.pd_ee_delta_pose.physx_cpu.h5")
    dataset = ManiSkillTrajectoryDataset(converted)
    assert len(dataset) > 100
    sample = dataset[0]
    assert sample["action"].shape == (7,) and sample["obs"].ndim == 1
    # the oracle paces its motions so that the converted demonstrations still succeed within the time limit
    # (imitation learners can only learn what the episode leaves time for)
    limit = gym.spec("SampleCollection-v1").max_episode_steps
    with h5py.File(converted) as trajectories:
        successes = [trajectory["success"][:] for trajectory in trajectories.values()]
    assert all(success.any() for success in successes)
    first_successes = [int(np.argmax(success)) for success in successes]
    assert max(first_successes) < limit, first_successes


def test_demos_are_recorded_natively_in_ee_delta_pose_and_replay_to_success(tmp_path):
    args = demos.Args(env_id="PegInHoleAssembly-v1", control_mode="pd_ee_delta_pose", num_traj=1, num_procs=1, record_dir=str(tmp_path), traj_name="ee", env_kwargs='{"domain": "moon", "asset_source": "dataset"}', seed_start=6000)
    outcome = demos.main(args)
    meta = json.loads(open(outcome.path.replace(".h5", ".json")).read())
    assert meta["env_info"]["env_kwargs"]["control_mode"] == "pd_ee_delta_pose"
    episode = meta["episodes"][0]
    kwargs = {k: v for k, v in meta["env_info"]["env_kwargs"].items() if k not in ("render_mode",)}
    env = gym.make(meta["env_info"]["env_id"], **kwargs, render_backend="none")
    env.reset(**episode["reset_kwargs"])
    with h5py.File(outcome.path) as trajectories:
        actions = trajectories["traj_0"]["actions"][:]
        recorded_success = trajectories["traj_0"]["success"][:]
    assert actions.shape[1] == 7 and np.abs(actions).max() <= 1.0  # normalised end-effector deltas and the gripper
    assert recorded_success[-1] and len(actions) < gym.spec("PegInHoleAssembly-v1").max_episode_steps
    for action in actions:
        *_, info = env.step(action)
    assert bool(info["success"])  # the actions alone reproduce the demonstration
    env.close()


def test_demos_record_the_dense_reward_the_env_computes_when_asked(tmp_path):
    args = demos.Args(env_id="SampleCollection-v1", control_mode="pd_ee_delta_pose", num_traj=1, num_procs=1, record_dir=str(tmp_path), traj_name="rewarded", env_kwargs='{"domain": "moon", "asset_source": "dataset"}', seed_start=21, reward_mode="normalized_dense", record_rewards=True)
    path = demos.main(args).path
    with h5py.File(path) as trajectories:
        actions, rewards, success = (trajectories["traj_0"][key][:] for key in ("actions", "rewards", "success"))
    assert json.loads(open(path.replace(".h5", ".json")).read())["env_info"]["env_kwargs"]["reward_mode"] == "normalized_dense"
    env = gym.make("SampleCollection-v1", domain="moon", asset_source="dataset", control_mode="pd_ee_delta_pose", reward_mode="normalized_dense", render_backend="none")
    env.reset(seed=21)
    replayed = [float(env.step(action)[1]) for action in actions]
    env.close()
    np.testing.assert_allclose(rewards, replayed, rtol=1e-6)
    assert success[-1] and rewards[-1] == 1.0 and rewards[0] < 0.5  # the normalised reward: 1 once solved, less before


@pytest.mark.parametrize("control_mode, noise_std", [("pd_ee_delta_pose", 0.05), ("pd_joint_pos", 0.003)])
def test_noisy_demos_record_the_oracles_actions_and_the_executed_states(tmp_path, control_mode, noise_std):
    def record(noise):
        args = demos.Args(env_id="SampleCollection-v1", control_mode=control_mode, num_traj=1, num_procs=1, record_dir=str(tmp_path), traj_name=f"noise{noise}", env_kwargs='{"domain": "moon", "asset_source": "dataset"}', seed_start=21, action_noise=noise)
        with h5py.File(demos.main(args).path) as trajectories:
            return trajectories["traj_0"]["actions"][:], trajectories["traj_0"]["env_states"]["articulations"]["panda"][:]

    clean_actions, clean_states = record(0.0)
    noisy_actions, noisy_states = record(noise_std)
    again_actions, again_states = record(noise_std)
    np.testing.assert_array_equal(noisy_actions, again_actions)  # the noise is drawn from the episode's seed
    np.testing.assert_array_equal(noisy_states, again_states)
    both_states = min(len(clean_states), len(noisy_states))
    assert np.abs(noisy_states[:both_states] - clean_states[:both_states]).max() > 1e-3  # the executed motion was perturbed
    np.testing.assert_array_equal(noisy_actions[0], clean_actions[0])  # the oracle's first action, not the noisy one executed
    both_actions = min(len(clean_actions), len(noisy_actions))
    assert not np.allclose(noisy_actions[:both_actions], clean_actions[:both_actions])
    # the recorded actions are the oracle's own, not the executed (noisy) ones: replaying them does not retrace the
    # recorded states, as replaying a clean demonstration does
    env = gym.make("SampleCollection-v1", domain="moon", asset_source="dataset", control_mode=control_mode, render_backend="none")
    assert (noisy_actions >= env.action_space.low).all() and (noisy_actions <= env.action_space.high).all()
    env.reset(seed=21)
    for action in noisy_actions[:30]:
        env.step(action)
    assert np.abs(env.unwrapped.get_state_dict()["articulations"]["panda"][0].numpy() - noisy_states[30]).max() > 1e-4
    env.close()
