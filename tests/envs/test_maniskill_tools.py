"""Our envs work with ManiSkill's wrappers and gymnasium's CPU vectorisation, as researchers use them."""

import json

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
