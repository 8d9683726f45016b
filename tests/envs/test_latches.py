"""Sockets latch what is seated in them: in zero gravity a released peg (or panel) stays in, and nothing that is
not seated is captured."""

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch

from mani_skill_space.envs import insertion
from mani_skill_space.envs.insertion import LATCH_ACCELERATION, LATCH_DAMPING, latch_force

RELEASE_DRIFT = 0.002
"""m/s out of the seat: about what letting go of a part leaves it with in orbit."""
RELEASE_SPIN = (0.01, -0.01, 0.02)
FIVE_SECONDS = 100
"""Control steps (20 Hz)."""


def test_latch_force_is_batched_and_zero_where_not_engaged():
    n = 8
    engaged = torch.tensor([True, False] * 4)
    into = torch.nn.functional.normalize(torch.randn(n, 3), dim=-1)
    velocity = torch.randn(n, 3) * 0.01
    mass = torch.rand(n) + 0.05
    force = latch_force(engaged, into, velocity, mass)
    expected = mass[:, None] * (LATCH_ACCELERATION * into - LATCH_DAMPING * velocity)
    assert force.shape == (n, 3)
    torch.testing.assert_close(force[engaged], expected[engaged])
    assert torch.all(force[~engaged] == 0.0)
    # batched over pegs too: (n, k, 3)
    assert latch_force(engaged[:, None].expand(n, 4), into[:, None].expand(n, 4, 3), velocity[:, None].expand(n, 4, 3), mass[:, None].expand(n, 4)).shape == (n, 4, 3)


def _orbit(env_id: str, **kwargs):
    env = gym.make(env_id, domain="orbit", render_backend="none", obs_mode="state", control_mode="pd_joint_pos", **kwargs)
    env.reset(seed=3)
    return env


def _seat(actor, seat: np.ndarray, part_frame: np.ndarray, height: float, outward: np.ndarray):
    """Put ``actor`` with its ``part_frame`` at ``seat`` raised ``height`` along ``outward``, drifting out of it."""
    goal = seat.copy()
    goal[:3, 3] += outward * height
    actor.set_pose(sapien.Pose(goal @ np.linalg.inv(part_frame)))
    actor.set_linear_velocity(torch.as_tensor(outward * RELEASE_DRIFT, dtype=torch.float32)[None])
    actor.set_angular_velocity(torch.tensor([RELEASE_SPIN]))


def _hold_arm(env, steps: int, measure):
    hold = env.unwrapped.agent.robot.get_qpos()[:, :8].clone()
    readings = []
    for _ in range(steps):
        env.step(hold)
        readings.append(measure())
    return readings


def _release_peg(env, inserted_fraction: float):
    u = env.unwrapped
    bottom = u.insertion.hole_bottom[0, 0].numpy().astype(np.float64)
    depth = float(u.insertion.hole_depth[0, 0])
    end = u.insertion.peg_ends[0, 0, 0].numpy().astype(np.float64)
    _seat(u.peg, bottom, end, (1.0 - inserted_fraction) * depth + 2e-4, bottom[:3, 2])


@pytest.mark.parametrize("asset_source", ["procedural", "dataset"])
def test_inserted_peg_stays_inserted_for_five_seconds_in_orbit_after_release(asset_source, monkeypatch):
    env = _orbit("PegInHoleAssembly-v1", asset_source=asset_source)
    _release_peg(env, 1.0)
    success = _hold_arm(env, FIVE_SECONDS, lambda: bool(env.unwrapped.evaluate()["success"][0]))
    assert all(success)
    # without the latch the same release drifts out of the hole
    monkeypatch.setattr(insertion, "LATCH_ACCELERATION", 0.0)
    monkeypatch.setattr(insertion, "LATCH_DAMPING", 0.0)
    env.reset(seed=3)
    _release_peg(env, 1.0)
    assert not _hold_arm(env, FIVE_SECONDS, lambda: bool(env.unwrapped.evaluate()["success"][0]))[-1]
    env.close()


def test_peg_that_is_not_inserted_is_not_captured():
    env = _orbit("PegInHoleAssembly-v1", asset_source="procedural")
    _release_peg(env, 0.6)
    fractions = _hold_arm(env, FIVE_SECONDS, lambda: float(env.unwrapped.evaluate()["inserted_fraction"][0]))
    assert fractions[-1] < 0.5
    assert np.all(np.diff(fractions) < 1e-4)  # it never moves back in
    env.close()


def test_released_pegs_and_panel_stay_assembled_for_five_seconds_in_orbit():
    env = _orbit("SolarPanelAssembly-v1")
    u = env.unwrapped
    for socket in range(4):
        bottom = u.insertion.hole_bottom[0, socket].numpy().astype(np.float64)
        _seat(u.pegs[socket], bottom, u.insertion.peg_ends[0, socket, 0].numpy().astype(np.float64), 1e-4, bottom[:3, 2])
    target = u.panel_target[0].numpy().astype(np.float64)
    _seat(u.panel, target, u._seat_in_panel[0].numpy().astype(np.float64), 1e-4, target[:3, 2])
    success = _hold_arm(env, FIVE_SECONDS, lambda: bool(u.evaluate()["success"][0]))
    assert all(success[10:])  # the panel settles onto the pegs' tops within half a second
    env.close()
