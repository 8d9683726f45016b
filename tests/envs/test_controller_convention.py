"""Pins ManiSkill 3.0.1's ``pd_ee_delta_pose`` conventions on our envs (see ``envs/base.py``).

Translation actions move the TCP along the arm-base axes; rotation actions are XYZ Euler deltas whose sign is
inverted in 3.0.1 (ManiSkill issue #1469). If an upgrade fixes the sign, this test fails on purpose: the
oracle, the demonstrations and the documentation then need to follow.
"""

import gymnasium as gym
import numpy as np
import pytest
import torch
from mani_skill.utils.geometry.rotation_conversions import matrix_to_euler_angles, quaternion_to_matrix

import mani_skill_space  # noqa: F401


def _tcp_after(action, steps=4):
    env = gym.make("SampleCollection-v1", obs_mode="state", render_backend="none", domain="earth")
    env.reset(seed=0)
    start = env.unwrapped.agent.tcp.pose
    for _ in range(steps):
        env.step(torch.as_tensor(action, dtype=torch.float32))
    end = env.unwrapped.agent.tcp.pose
    relative = quaternion_to_matrix(end.q)[0] @ quaternion_to_matrix(start.q)[0].T  # rotation in the world frame
    env.close()
    return (end.p - start.p)[0].numpy(), matrix_to_euler_angles(relative, "XYZ").numpy()


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_positive_translation_action_moves_the_tcp_along_that_axis(axis):
    action = np.zeros(7)
    action[axis], action[6] = 0.5, 1.0
    moved, _ = _tcp_after(action)
    assert moved[axis] > 0.02
    assert np.abs(np.delete(moved, axis)).max() < 0.5 * moved[axis]


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_positive_rotation_action_turns_the_tcp_negatively_in_maniskill_3_0_1(axis):
    action = np.zeros(7)
    action[3 + axis], action[6] = 0.5, 1.0
    _, turned = _tcp_after(action)
    assert turned[axis] < -0.05
