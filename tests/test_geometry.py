import torch
from mani_skill.utils.geometry.rotation_conversions import quaternion_to_matrix
from mani_skill.utils.structs.pose import Pose

from mani_skill_space.geometry import in_open_box, relative_pose, rotation_6d, rotation_matrix

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
