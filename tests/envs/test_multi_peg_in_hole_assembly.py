"""MultiPegInHoleAssembly-v1: four pegs lying in their lanes, four hole modules, success when every hole holds a
peg it fits (any dataset socket, only its own procedural hole), a staged reward that rises with every filled hole,
the latches in orbit, and the four-pair layout."""

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch

from mani_skill_space.envs.multi_peg_in_hole_assembly import PAIR_COUNT, MultiPegInHoleAssemblyEnv, module_positions

SOURCES = MultiPegInHoleAssemblyEnv.SUPPORTED_ASSET_SOURCES


def make(**kwargs):
    kwargs.setdefault("render_backend", "none")
    kwargs.setdefault("obs_mode", "state")
    return gym.make("MultiPegInHoleAssembly-v1", **kwargs)


def _insert(env, peg: int, hole: int, height: float = 0.0):
    """Put ``peg``'s first insertable end on ``hole``'s axis, ``height`` above its bottom, at rest."""
    u = env.unwrapped
    bottom = u.insertion.hole_bottom[0, hole].numpy().astype(np.float64)
    goal = bottom.copy()
    goal[:3, 3] += bottom[:3, 2] * height
    u.pegs[peg].set_pose(sapien.Pose(goal @ np.linalg.inv(u.insertion.peg_ends[0, peg, 0].numpy().astype(np.float64))))
    u.pegs[peg].set_linear_velocity(torch.zeros(1, 3))
    return u.get_info()


@pytest.mark.parametrize("asset_source", SOURCES)
def test_four_pegs_lie_at_rest_in_front_of_four_modules(asset_source):
    env = make(asset_source=asset_source)
    env.reset(seed=1)
    u = env.unwrapped
    assert len(u.pegs) == len(u.hole_modules) == PAIR_COUNT
    modules = torch.stack([module.pose.p[0] for module in u.hole_modules])
    np.testing.assert_allclose(modules.numpy(), module_positions(asset_source), atol=1e-6)
    pegs = torch.stack([peg.pose.p[0] for peg in u.pegs])
    assert torch.all(pegs[:, 0] < modules[:, 0] - 0.2)
    assert torch.all(pegs[:-1, 1] > pegs[1:, 1])  # each in its own lane, in the modules' order
    info = u.get_info()
    assert info["stage"].item() == 0 and not info["success"].item()
    if asset_source == "procedural":  # four distinct pairs, each passed its feasibility check
        depths = u.insertion.hole_depth[0]
        assert len(set(depths.tolist())) == PAIR_COUNT
        assert all("feasibility" in u.hole_assets[i][0].info for i in range(PAIR_COUNT))
        # each peg lies on a face its arm check passed (envs.arm_reach)
        assert all(u.hole_assets[i][0].info["feasibility"]["checks"][0] == "arm_inserts" for i in range(PAIR_COUNT))
        assert all(bool(u._peg_placements[i].allowed[0].any()) for i in range(PAIR_COUNT))
        assert all(u._peg_placements[i].allowed[0, : len(u.peg_assets[i][0].info["insertable_faces"])].tolist() == u.peg_assets[i][0].info["insertable_faces"] for i in range(PAIR_COUNT))
    env.close()


@pytest.mark.parametrize("asset_source", SOURCES)
def test_success_needs_every_hole_filled_and_the_stage_counts_them(asset_source):
    env = make(asset_source=asset_source)
    env.reset(seed=2)
    for filled in range(PAIR_COUNT):
        info = _insert(env, filled, filled)
        assert info["stage"].item() == filled + 1
        assert info["success"].item() == (filled == PAIR_COUNT - 1)
    # a peg only 80% in leaves its hole empty
    info = _insert(env, 0, 0, height=0.2 * env.unwrapped.insertion.hole_depth[0, 0].item())
    assert info["stage"].item() == PAIR_COUNT - 1 and not info["success"].item()
    env.close()


def test_a_dataset_peg_fits_any_socket_and_a_procedural_peg_only_its_own_hole():
    env = make(asset_source="dataset")
    env.reset(seed=3)
    info = _insert(env, 0, 2)
    assert info["hole_filled"][0].tolist() == [False, False, True, False] and info["peg_inserted"][0, 0]
    env.close()
    env = make(asset_source="procedural")
    env.reset(seed=3)
    info = _insert(env, 0, 2)  # deep in hole 2's bore position, but not its shape
    assert not info["hole_filled"][0].any()
    env.close()


def test_the_staged_reward_rises_with_every_filled_hole_and_peaks_at_success():
    env = make(reward_mode="dense", asset_source="dataset")
    env.reset(seed=4)
    u = env.unwrapped
    rewards = [u.get_reward(obs=None, action=torch.zeros(1, 7), info=u.get_info()).item()]
    for hole in range(PAIR_COUNT):
        info = _insert(env, hole, hole)
        rewards.append(u.get_reward(obs=None, action=torch.zeros(1, 7), info=info).item())
    assert all(later > earlier for earlier, later in zip(rewards, rewards[1:]))
    assert rewards[-1] == MultiPegInHoleAssemblyEnv.REWARD_TABLE.max_reward == 5 * 169.0
    env.close()


def test_released_pegs_stay_in_their_holes_in_orbit():
    env = make(domain="orbit", asset_source="procedural", control_mode="pd_joint_pos")
    env.reset(seed=5)
    u = env.unwrapped
    for hole in range(PAIR_COUNT):
        _insert(env, hole, hole, height=2e-4)
        u.pegs[hole].set_linear_velocity(torch.as_tensor(u.insertion.hole_bottom[0, hole, :3, 2] * 0.02)[None])
    hold = u.agent.robot.get_qpos()[:, :8].clone()
    for _ in range(100):  # 5 s
        _, _, _, _, info = env.step(hold)
        assert info["success"].item()
    env.close()


def test_state_observation_has_every_peg_and_hole():
    env = make(obs_mode="state_dict")
    obs, _ = env.reset(seed=0)
    extra = obs["extra"]
    assert extra["pegs_pos_in_tcp"].shape == (1, 3 * PAIR_COUNT)
    assert extra["holes_pos_in_tcp"].shape == (1, 3 * PAIR_COUNT)
    assert extra["hole_filled"].shape == (1, PAIR_COUNT) and extra["grasped"].shape == (1, PAIR_COUNT)
    env.close()
