import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch

from mani_skill_space.envs import SampleCollectionEnv

ENV_ID = "SampleCollection-v1"
DOMAINS = SampleCollectionEnv.SUPPORTED_DOMAINS
SOURCES = SampleCollectionEnv.SUPPORTED_ASSET_SOURCES


def make(**kwargs):
    kwargs.setdefault("render_backend", "none")
    kwargs.setdefault("obs_mode", "state")
    return gym.make(ENV_ID, **kwargs)


def test_other_control_modes_work():
    for mode in ("pd_joint_delta_pos", "pd_joint_pos", "pd_ee_delta_pos"):
        env = make(control_mode=mode)
        env.reset(seed=0)
        _, reward, *_ = env.step(env.action_space.sample())
        assert torch.isfinite(reward).all()
        env.close()


def test_cameras_are_base_and_wrist_rgbd_at_64_by_64():
    env = make(obs_mode="rgbd", render_backend="cpu")
    obs, _ = env.reset(seed=0)
    for camera in ("base_camera", "wrist_camera"):
        data = obs["sensor_data"][camera]
        assert data["rgb"].shape == (1, 64, 64, 3) and data["rgb"].dtype == torch.uint8
        assert data["depth"].shape == (1, 64, 64, 1) and data["depth"].dtype == torch.int16
        assert data["rgb"].float().std() > 5  # not a blank image
    env.close()


def test_sensor_configs_override_the_camera_size():
    env = make(obs_mode="rgb", render_backend="cpu", sensor_configs=dict(width=48, height=32))
    obs, _ = env.reset(seed=0)
    assert obs["sensor_data"]["base_camera"]["rgb"].shape == (1, 32, 48, 3)
    env.close()
    env = make(obs_mode="rgb", render_backend="cpu", sensor_configs=dict(wrist_camera=dict(width=96, height=96)))
    obs, _ = env.reset(seed=0)
    assert obs["sensor_data"]["wrist_camera"]["rgb"].shape == (1, 96, 96, 3)
    assert obs["sensor_data"]["base_camera"]["rgb"].shape == (1, 64, 64, 3)
    env.close()


def test_wrist_camera_robot_adds_its_hand_camera():
    env = make(robot_uids="panda_wristcam", obs_mode="rgb", render_backend="cpu")
    obs, _ = env.reset(seed=0)
    assert set(obs["sensor_data"]) == {"base_camera", "wrist_camera", "hand_camera"}
    env.close()


def _sample_state(env):
    u = env.unwrapped
    return u._placement.points.clone(), u.sample.pose.raw_pose.clone(), u.agent.robot.get_qpos().clone()


def test_reconfiguration_resamples_the_rock():
    env = make()
    env.reset(seed=1)
    first = env.unwrapped._placement.points.clone()
    env.reset(seed=2)
    assert env.unwrapped._placement.points.shape != first.shape or not torch.equal(env.unwrapped._placement.points, first)
    env.close()
    env = make(reconfiguration_freq=0)
    env.reset(seed=1)
    kept = env.unwrapped._placement.points.clone()
    env.reset(seed=2)
    torch.testing.assert_close(env.unwrapped._placement.points, kept)
    env.close()


def _place_sample(env, position, velocity=(0.0, 0.0, 0.0)):
    u = env.unwrapped
    u.sample.set_pose(sapien.Pose(p=position))
    u.sample.set_linear_velocity(torch.tensor([velocity]))
    u.sample.set_angular_velocity(torch.zeros(1, 3))
    return u.evaluate()


@pytest.mark.parametrize("asset_source", SOURCES)
def test_sample_resting_in_the_bin_is_success_and_on_the_ground_is_not(asset_source):
    env = make(asset_source=asset_source)
    env.reset(seed=0)
    u = env.unwrapped
    inside = (u.bin_target[0] - torch.tensor([0, 0, 0.03])).tolist()
    assert _place_sample(env, inside)["success"].item()
    assert not _place_sample(env, inside, velocity=(0, 0, -0.5))["success"].item()  # still falling: not resting
    assert not _place_sample(env, [0.55, 0.0, 0.03])["success"].item()
    assert not _place_sample(env, (u.bin_target[0] + torch.tensor([0, 0, 0.2])).tolist())["success"].item()  # above the rim
    assert not _place_sample(env, (u.bin_target[0] + torch.tensor([0.3, 0, 0])).tolist())["success"].item()  # beside the bin
    env.close()


@pytest.mark.parametrize("asset_source", SOURCES)
def test_sample_starts_at_rest_on_the_ground_in_front_of_the_rover(asset_source):
    for domain in DOMAINS:
        env = make(domain=domain, asset_source=asset_source)
        for seed in range(3):
            env.reset(seed=seed)
            start = env.unwrapped.sample.pose.raw_pose.clone()
            assert 0.45 <= start[0, 0].item() <= 0.65 and abs(start[0, 1].item()) <= 0.2
            for _ in range(20):
                env.step(torch.zeros(1, 7))
            end = env.unwrapped.sample.pose.raw_pose
            assert torch.linalg.norm(end[0, :3] - start[0, :3]).item() < 0.005, (domain, seed)
            turned = np.degrees(2 * np.arccos(min(1.0, abs(torch.dot(end[0, 3:], start[0, 3:]).item()))))
            # a rock hardly turns; the tube (a 24-sided prism) may roll onto a neighbouring side (15 deg)
            assert turned < (5.0 if asset_source == "procedural" else 16.0), (domain, seed, turned)
        env.close()


def test_per_env_sample_is_a_merged_actor_in_the_state_registry():
    env = make()
    env.reset(seed=0)
    state = env.unwrapped.get_state_dict()
    assert "sample" in state["actors"]
    assert not any(name.startswith("sample-") for name in state["actors"])
    env.close()


def test_state_round_trip_restores_the_observation():
    env = make(obs_mode="state_dict")
    env.reset(seed=9)
    state = env.unwrapped.get_state_dict()
    obs = env.unwrapped.get_obs()
    for _ in range(15):
        env.step(env.action_space.sample())
    env.unwrapped.set_state_dict(state)
    restored = env.unwrapped.get_obs()
    # the state carries the elapsed steps and the wrist wrench too, so every entry comes back
    for group in ("agent", "extra"):
        assert restored[group].keys() == obs[group].keys()
        for name in obs[group]:
            torch.testing.assert_close(restored[group][name], obs[group][name], atol=1e-5, rtol=1e-5, msg=f"{group}/{name}")
    env.close()


def test_shared_observations_start_at_the_expected_values():
    env = make(obs_mode="state_dict")
    obs, _ = env.reset(seed=0)
    extra = obs["extra"]
    assert extra["time_remaining"].item() == 1.0
    assert extra["gripper_opening"].item() == pytest.approx(1.0, abs=0.05)
    assert extra["tcp_rot6d"].shape == (1, 6) and extra["wrist_wrench"].shape == (1, 6)
    for _ in range(15):
        obs, *_ = env.step(torch.zeros(1, 7))
    assert obs["extra"]["time_remaining"].item() == pytest.approx(1 - 15 / 150)
    assert env.unwrapped.steps_remaining().tolist() == [150 - 15]
    env.close()


def test_switching_control_mode_through_the_action_keeps_stepping():
    env = make()
    env.reset(seed=0)
    env.step(env.action_space.sample())
    qpos = env.unwrapped.agent.robot.get_qpos()[:, :8]
    _, reward, *_ = env.step({"control_mode": "pd_joint_pos", "action": qpos})
    assert env.unwrapped.control_mode == "pd_joint_pos" and torch.isfinite(reward).all()
    env.close()
