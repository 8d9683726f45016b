import pytest
import torch
from mani_skill.utils.geometry.rotation_conversions import axis_angle_to_quaternion, quaternion_to_matrix
from mani_skill.utils.structs.pose import Pose

from mani_skill_space.geometry import (
    in_open_box,
    insertion_measures,
    quaternion_multiply,
    relative_pose,
    rotation_6d,
    rotation_matrix,
    rotation_vector,
    step_velocities,
    twist_error,
)

NUM_ENVS = 8


def _random_poses(seed):
    generator = torch.Generator().manual_seed(seed)
    q = torch.randn(NUM_ENVS, 4, generator=generator)
    q = q / q.norm(dim=-1, keepdim=True)
    return torch.randn(NUM_ENVS, 3, generator=generator), q


def test_rotation_matrix_matches_maniskill():
    _, q = _random_poses(0)
    torch.testing.assert_close(rotation_matrix(q), quaternion_to_matrix(q))


def test_relative_pose_matches_maniskill_pose_algebra_on_8_envs():
    (pa, qa), (pb, qb) = _random_poses(1), _random_poses(2)
    expected = Pose.create_from_pq(pa, qa).inv() * Pose.create_from_pq(pb, qb)
    position, rotation = relative_pose(pa, rotation_matrix(qa), pb, rotation_matrix(qb))
    torch.testing.assert_close(position, expected.p, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(rotation, quaternion_to_matrix(expected.q), atol=1e-5, rtol=1e-5)


def test_rotation_6d_is_the_first_two_columns_row_major():
    matrix = torch.arange(9.0).reshape(1, 3, 3).repeat(NUM_ENVS, 1, 1)
    assert rotation_6d(matrix).tolist() == [[0.0, 1.0, 3.0, 4.0, 6.0, 7.0]] * NUM_ENVS


def test_in_open_box_on_8_envs():
    floor = torch.tensor([-0.6, 0.0, 0.2])
    half = torch.tensor([0.15, 0.17, 0.06])
    points = torch.tensor(
        [
            [-0.6, 0.0, 0.25],  # centre
            [-0.46, 0.16, 0.21],  # near a corner, inside
            [-0.44, 0.0, 0.25],  # through the +x wall
            [-0.6, -0.18, 0.25],  # through the -y wall
            [-0.6, 0.0, 0.19],  # below the floor
            [-0.6, 0.0, 0.33],  # above the rim
            [-0.6, 0.0, 0.32],  # just below the rim
            [0.55, 0.0, 0.02],  # on the ground in front of the rover
        ]
    )
    assert in_open_box(points, floor, half).tolist() == [True, True, False, False, False, False, True, False]


def _frame(position, rotation=None):
    frame = torch.eye(4)
    frame[:3, 3] = torch.tensor(position, dtype=torch.float32)
    if rotation is not None:
        frame[:3, :3] = rotation
    return frame


def _rot_z(angle):
    c, s = torch.cos(torch.tensor(angle)), torch.sin(torch.tensor(angle))
    return torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_twist_error_respects_the_symmetry_order_on_8_envs():
    angles = torch.tensor([0.0, torch.pi / 2, torch.pi / 4, torch.pi, torch.pi / 2, 0.3, torch.pi, torch.pi / 3])
    orders = torch.tensor([4, 4, 4, 2, 2, 0, 1, 3])
    tip_x = torch.stack([torch.cos(angles), torch.sin(angles), torch.zeros(8)], dim=-1)
    hole_x = torch.tensor([[1.0, 0.0, 0.0]]).repeat(8, 1)
    axis = torch.tensor([[0.0, 0.0, 1.0]]).repeat(8, 1)
    error = twist_error(tip_x, hole_x, axis, orders)
    torch.testing.assert_close(error, torch.tensor([0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 1.0]), atol=1e-5, rtol=0)


def test_insertion_measures_on_8_envs():
    depth = torch.full((NUM_ENVS,), 0.02)
    bottom = torch.stack([_frame([0.6, 0.0, 0.08])] * NUM_ENVS)
    entrance = torch.stack([_frame([0.6, 0.0, 0.10])] * NUM_ENVS)
    heights = [0.0, 0.002, 0.01, 0.02, 0.05, 0.0, 0.0, 0.0]
    tilts = [0.0, 0.0, 0.0, 0.0, 0.0, 0.2, 0.0, 0.0]
    lateral = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.004, 0.0]
    twists = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, torch.pi / 4]
    tips = []
    for h, tilt, dx, twist in zip(heights, tilts, lateral, twists):
        c, s = torch.cos(torch.tensor(tilt)), torch.sin(torch.tensor(tilt))
        tilted = torch.tensor([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]) @ _rot_z(twist)
        tips.append(_frame([0.6 + dx, 0.0, 0.08 + h], tilted))
    far_end = _frame([0.6, 0.0, 0.3])
    ends = torch.stack([torch.stack([tip, far_end]) for tip in tips])
    valid = torch.tensor([[True, True]] * NUM_ENVS)
    m = insertion_measures(ends, valid, entrance, bottom, depth, torch.full((NUM_ENVS,), 4))
    assert m["peg_end"].tolist() == [0] * NUM_ENVS  # the end nearer the entrance
    torch.testing.assert_close(m["inserted_fraction"][:5], torch.tensor([1.0, 0.9, 0.5, 0.0, -1.5]), atol=1e-5, rtol=0)
    assert m["axis_angle"][5].item() == pytest.approx(0.2, abs=1e-5) and m["axis_angle"][0].item() == pytest.approx(0.0, abs=1e-3)
    assert m["lateral_offset"][6].item() == pytest.approx(0.004, abs=1e-6)
    assert m["twist_error"][7].item() == pytest.approx(1.0, abs=1e-5) and m["twist_error"][0].item() == pytest.approx(0.0, abs=1e-5)
    invalid_first = torch.tensor([[False, True]] * NUM_ENVS)
    assert insertion_measures(ends, invalid_first, entrance, bottom, depth, torch.full((NUM_ENVS,), 4))["peg_end"].tolist() == [1] * NUM_ENVS


def test_step_velocities_recover_known_motions_on_8_envs():
    generator = torch.Generator().manual_seed(0)
    velocity = torch.randn(NUM_ENVS, 3, generator=generator)
    spin = torch.randn(NUM_ENVS, 3, generator=generator) * 3  # up to ~10 rad/s
    spin[0] = 0.0  # no turn at all
    spin[1] = torch.tensor([0.0, 0.0, 1e-5])  # almost none
    dt = 0.05
    start_q = axis_angle_to_quaternion(torch.randn(NUM_ENVS, 3, generator=generator))
    start_q[2] = -start_q[2]  # the same orientation, the other sign
    start_p = torch.randn(NUM_ENVS, 3, generator=generator)
    end_q = quaternion_multiply(axis_angle_to_quaternion(spin * dt), start_q)  # turned about world axes
    end_q[3] = -end_q[3]
    linear, angular = step_velocities(start_p, start_q, start_p + velocity * dt, end_q, dt)
    torch.testing.assert_close(linear, velocity, atol=1e-4, rtol=1e-4)
    torch.testing.assert_close(angular, spin, atol=1e-3, rtol=1e-3)


def test_rotation_vector_takes_the_short_way_round():
    turn = torch.tensor([[0.0, 0.0, 1.5 * torch.pi]])  # three quarters of a turn = a quarter turn back
    torch.testing.assert_close(rotation_vector(axis_angle_to_quaternion(turn)), torch.tensor([[0.0, 0.0, -0.5 * torch.pi]]))


def test_pose_error_on_eight_envs_with_half_turn_symmetry():
    from mani_skill_space.geometry import pose_error

    n = 8
    target = torch.eye(4).repeat(n, 1, 1)
    target[:, :3, 3] = torch.tensor([0.55, 0.0, 0.28])
    yaw = torch.linspace(0.0, torch.pi, n)
    pose = target.clone()
    pose[:, 0, 0], pose[:, 0, 1], pose[:, 1, 0], pose[:, 1, 1] = torch.cos(yaw), -torch.sin(yaw), torch.sin(yaw), torch.cos(yaw)
    pose[:, 0, 3] += torch.arange(n) * 0.01
    distance, angle = pose_error(pose, target)
    torch.testing.assert_close(distance, torch.arange(n) * 0.01, atol=1e-6, rtol=0)
    torch.testing.assert_close(angle, yaw, atol=1e-3, rtol=0)
    _, symmetric = pose_error(pose, target, half_turn_symmetric=True)
    torch.testing.assert_close(symmetric, torch.minimum(yaw, torch.pi - yaw), atol=1e-3, rtol=0)
