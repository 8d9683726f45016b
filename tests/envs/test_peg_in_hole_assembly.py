import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch

from mani_skill_space.envs import PegInHoleAssemblyEnv
from mani_skill_space.envs.peg_in_hole_assembly import module_position

ENV_ID = "PegInHoleAssembly-v1"
DOMAINS = PegInHoleAssemblyEnv.SUPPORTED_DOMAINS
SOURCES = PegInHoleAssemblyEnv.SUPPORTED_ASSET_SOURCES


def make(**kwargs):
    kwargs.setdefault("render_backend", "none")
    kwargs.setdefault("obs_mode", "state")
    return gym.make(ENV_ID, **kwargs)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(asset_source="dataset", clearance=0.002), "clearance applies to procedural assets only"),
        (dict(clearance=0.0), "clearance must be positive"),
        (dict(clearance=-0.001), "clearance must be positive"),
    ],
)
def test_bad_kwargs(kwargs, message):
    with pytest.raises(ValueError, match=message):
        make(**kwargs)


def test_clearance_sets_the_procedural_hole():
    env = make(clearance=0.003)
    env.reset(seed=0)
    assert env.unwrapped.hole_assets[0].info["clearance"] == 0.003
    env.close()


def test_in_orbit_nothing_drifts_at_reset():
    env = make(domain="orbit")
    assert env.unwrapped.scene.px.config.gravity.tolist() == [0.0, 0.0, 0.0]
    for seed in range(3):
        env.reset(seed=seed)
        start = env.unwrapped.peg.pose.raw_pose.clone()
        for _ in range(30):
            env.step(torch.zeros(1, 7))
        assert torch.allclose(env.unwrapped.peg.pose.raw_pose, start, atol=1e-4)
        assert torch.linalg.norm(env.unwrapped.peg.linear_velocity).item() < 1e-4
    env.close()


@pytest.mark.parametrize("asset_source", SOURCES)
def test_peg_starts_at_rest_lying_in_front_of_the_module(asset_source):
    for domain in ("moon", "earth"):
        env = make(domain=domain, asset_source=asset_source)
        for seed in range(3):
            env.reset(seed=seed)
            u = env.unwrapped
            start = u.peg.pose.raw_pose.clone()
            for _ in range(20):
                env.step(torch.zeros(1, 7))
            assert torch.linalg.norm(u.peg.pose.p - start[:, :3]).item() < 0.005, (domain, seed)
            tip = u.peg_end_frames()[0, 0, 0]
            assert abs(tip[2, 2].item()) < 0.35  # lying: the axis is roughly horizontal
            assert 0.24 - 0.005 <= module_position(asset_source)[0] - u.peg.pose.p[0, 0].item() <= 0.28 + 0.005
        env.close()


def _place_peg(env, height: float, twist: float = 0.0, tilt: float = 0.0, end: int = 0):
    """Put the peg's ``end`` on the hole's axis ``height`` above the bottom, turned and tilted."""
    u = env.unwrapped
    bottom = u.insertion.hole_bottom[0, 0].numpy().astype(np.float64)
    c, s = np.cos(twist), np.sin(twist)
    turn = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, height], [0, 0, 0, 1.0]])
    ct, st = np.cos(tilt), np.sin(tilt)
    lean = np.array([[1, 0, 0, 0], [0, ct, -st, 0], [0, st, ct, 0], [0, 0, 0, 1.0]])
    goal = bottom @ turn @ lean
    peg_pose = goal @ np.linalg.inv(u.insertion.peg_ends[0, 0, end].numpy().astype(np.float64))
    u.peg.set_pose(sapien.Pose(peg_pose))
    return u.evaluate()


@pytest.mark.parametrize("asset_source", SOURCES)
def test_success_needs_depth_and_alignment(asset_source):
    env = make(asset_source=asset_source)
    env.reset(seed=2)
    u = env.unwrapped
    depth = u.insertion.hole_depth[0, 0].item()
    order = int(u.insertion.symmetry_order[0, 0])
    assert _place_peg(env, 0.0)["success"].item()
    assert _place_peg(env, 0.05 * depth)["success"].item()
    assert not _place_peg(env, 0.2 * depth)["success"].item()  # only 80% in
    assert not _place_peg(env, depth + 0.02)["success"].item()  # above the entrance
    assert not _place_peg(env, 0.0, tilt=np.radians(10))["success"].item()
    if order >= 2:
        assert _place_peg(env, 0.0, twist=2 * np.pi / order)["success"].item()
    if asset_source == "dataset":  # both ends of the profile peg fit
        assert _place_peg(env, 0.0, end=1)["success"].item()
    env.close()


def test_a_seated_peg_gets_the_maximum_reward():
    env = make(reward_mode="dense")
    env.reset(seed=0)
    _place_peg(env, 0.0)
    info = env.unwrapped.get_info()
    assert info["success"].item()
    assert env.unwrapped.get_reward(obs=None, action=torch.zeros(1, 7), info=info).item() == PegInHoleAssemblyEnv.REWARD_TABLE.max_reward == 169.0
    env.close()


def test_state_observations_include_the_hole_frames_relative_to_the_peg():
    env = make(obs_mode="state_dict")
    obs, _ = env.reset(seed=0)
    extra = obs["extra"]
    for key, size in [("entrance_in_peg_end", 3), ("bottom_in_peg_end", 3), ("hole_rot6d_in_peg_end", 6), ("peg_rot6d_in_tcp", 6)]:
        assert extra[key].shape == (1, size)
    env.close()
