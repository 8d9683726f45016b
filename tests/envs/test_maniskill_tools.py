"""Our envs work with ManiSkill's wrappers and gymnasium's CPU vectorisation, as researchers use them."""

import json
import subprocess
import sys

import gymnasium as gym
import h5py
import numpy as np
from mani_skill.utils.wrappers.gymnasium import CPUGymWrapper
from mani_skill.utils.wrappers.record import RecordEpisode

import mani_skill_space  # noqa: F401


def _cpu_env():
    import mani_skill_space  # noqa: F401,F811  (registers the envs in the spawned worker)

    return CPUGymWrapper(gym.make("SampleCollection-v1", obs_mode="state", render_backend="none"), record_metrics=True)


def test_async_vector_env_of_cpu_envs_steps_with_reward_terms():
    envs = gym.vector.AsyncVectorEnv([_cpu_env, _cpu_env], context="spawn")
    try:
        obs, _ = envs.reset(seed=[0, 1])
        assert obs.shape[0] == 2 and not np.array_equal(obs[0], obs[1])
        for _ in range(3):
            obs, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
        assert reward.shape == (2,) and np.isfinite(reward).all()
        assert info["reward_terms"]["transport"].shape == (2,)
    finally:
        envs.close()


def test_record_episode_writes_trajectory_json_and_video(tmp_path):
    env = gym.make("SampleCollection-v1", domain="moon", obs_mode="state", render_mode="rgb_array")
    env = RecordEpisode(env, str(tmp_path), save_video=True, trajectory_name="traj", max_steps_per_video=10)
    env.reset(seed=0)
    for _ in range(5):
        env.step(env.action_space.sample())
    env.close()
    meta = json.loads((tmp_path / "traj.json").read_text())
    assert meta["env_info"]["env_id"] == "SampleCollection-v1"
    assert meta["env_info"]["max_episode_steps"] == 150
    assert meta["env_info"]["env_kwargs"]["domain"] == "moon"
    with h5py.File(tmp_path / "traj.h5") as trajectories:
        assert trajectories["traj_0"]["actions"].shape == (5, 7)
        assert "sample" in trajectories["traj_0"]["env_states"]["actors"]
    assert list(tmp_path.glob("*.mp4"))


def test_gymnasium_module_colon_id_form_makes_our_env():
    env = gym.make("mani_skill_space.envs:PegInHoleAssembly-v1", control_mode=None, obs_mode="state", render_backend="none")
    try:
        assert type(env.unwrapped).__name__ == "PegInHoleAssemblyEnv"
        assert env.unwrapped.control_mode == "pd_ee_delta_pose"
    finally:
        env.close()


def test_maniskill_demo_random_action_reaches_our_env_through_the_module_colon_id_form(tmp_path):
    """ManiSkill's own CLI, in a fresh process that never imports mani_skill_space itself: gymnasium imports
    ``mani_skill_space.envs`` for the ``module:EnvId`` id, which registers our envs."""
    command = [sys.executable, "-m", "mani_skill.examples.demo_random_action", "-e", "mani_skill_space.envs:SampleCollection-v1"]
    result = subprocess.run(command + ["--render-mode", "none", "--seed", "0"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    assert "Control mode pd_ee_delta_pose" in result.stdout
    assert result.stdout.count("\ntruncated") == 150  # a whole episode: 7.5 s at 20 Hz
