"""The debris start check (``mani_skill_space.debris_paths``): batched, sim-free."""

import numpy as np
import torch

from mani_skill_space.debris_paths import (
    CANDIDATE_STARTS,
    HAND_READY_TIME,
    LATEST_MEETING,
    MIN_SECONDS_WITHIN_REACH,
    POST_CLEARANCE,
    REACH,
    SHOULDER_HEIGHT,
    TIME_STEP,
    first_catchable,
    seconds_to_camera_post,
    seconds_within_reach,
    tumbling_rotations,
)
from mani_skill_space.procgen.mounts import ARM_MOUNT_HEIGHT, BASE_CAMERA_POST_TOP, BASE_CAMERA_POST_XY

SHOULDER = torch.tensor([0.0, 0.0, ARM_MOUNT_HEIGHT + SHOULDER_HEIGHT])
ZERO_G = torch.zeros(3)


def test_a_path_through_the_reach_shell_counts_the_time_it_spends_there():
    # drifting straight at the shoulder along x at 0.1 m/s from 1.2 m: within 0.4-0.8 m for 4 s (t = 4..8 s)
    seconds = seconds_within_reach(torch.tensor([1.2, 0.0, SHOULDER[2]]), torch.tensor([-0.1, 0.0, 0.0]), ZERO_G, SHOULDER)
    assert abs(float(seconds) - 4.0) <= 2 * TIME_STEP


def test_time_before_the_hand_is_ready_and_after_the_latest_meeting_does_not_count():
    # inside the shell from the start, leaving it (toward the shoulder) at 1 s: none of it after HAND_READY_TIME
    early = seconds_within_reach(torch.tensor([0.5, 0.0, SHOULDER[2]]), torch.tensor([-0.1, 0.0, 0.0]), ZERO_G, SHOULDER)
    assert float(early) == 0.0
    still = seconds_within_reach(torch.tensor([0.6, 0.0, SHOULDER[2]]), torch.zeros(3), ZERO_G, SHOULDER)
    assert abs(float(still) - (LATEST_MEETING - HAND_READY_TIME)) <= 2 * TIME_STEP


def test_out_of_reach_below_the_meeting_height_or_falling_through_the_ground_never_counts():
    far = seconds_within_reach(torch.tensor([REACH[1] + 0.3, 0.0, SHOULDER[2]]), torch.zeros(3), ZERO_G, SHOULDER)
    low = seconds_within_reach(torch.tensor([0.6, 0.0, 0.05]), torch.zeros(3), ZERO_G, SHOULDER)
    falling = seconds_within_reach(torch.tensor([0.6, 0.0, 0.5]), torch.zeros(3), torch.tensor([0.0, 0.0, -9.81]), SHOULDER)
    assert float(far) == float(low) == 0.0
    assert float(falling) == 0.0  # it is on the ground before the hand is ready


def test_time_after_the_path_strikes_the_base_camera_post_does_not_count():
    # along x at 0.3 m/s, 5 cm above the arm's base (below the camera's head), straight through the post: within reach
    # in front of the arm for about 1.55 s (x 0.75 -> 0.28), then, had it flown through the post and the arm, behind it
    position, velocity = torch.tensor([1.2, 0.0, ARM_MOUNT_HEIGHT + 0.05]), torch.tensor([-0.3, 0.0, 0.0])
    through = seconds_within_reach(position, velocity, ZERO_G, SHOULDER, camera_post=False)
    struck = seconds_within_reach(position, velocity, ZERO_G, SHOULDER)
    assert abs(float(through) - 3.1) <= 3 * TIME_STEP
    assert abs(float(struck) - 1.55) <= 2 * TIME_STEP
    base = SHOULDER - torch.tensor([0.0, 0.0, SHOULDER_HEIGHT])
    assert abs(float(seconds_to_camera_post(position, velocity, ZERO_G, base)) - (1.2 - BASE_CAMERA_POST_XY[0] - POST_CLEARANCE) / 0.3) <= TIME_STEP


def test_a_path_beside_or_above_the_camera_post_is_not_cut_short():
    base = SHOULDER - torch.tensor([0.0, 0.0, SHOULDER_HEIGHT])
    beside = torch.tensor([1.2, BASE_CAMERA_POST_XY[1] + POST_CLEARANCE + 0.02, ARM_MOUNT_HEIGHT + 0.05])
    above = torch.tensor([1.2, 0.0, ARM_MOUNT_HEIGHT + BASE_CAMERA_POST_TOP + POST_CLEARANCE + 0.02])
    velocity = torch.tensor([-0.3, 0.0, 0.0])
    for position in (beside, above):
        assert torch.isinf(seconds_to_camera_post(position, velocity, ZERO_G, base))
        assert torch.equal(seconds_within_reach(position, velocity, ZERO_G, SHOULDER), seconds_within_reach(position, velocity, ZERO_G, SHOULDER, camera_post=False))


def test_batched_over_envs_and_candidates():
    generator = torch.Generator().manual_seed(0)
    position = torch.rand(8, CANDIDATE_STARTS, 3, generator=generator) + torch.tensor([0.5, -0.5, 0.3])
    velocity = (torch.rand(8, CANDIDATE_STARTS, 3, generator=generator) - 0.5) * 0.4
    shoulders = SHOULDER + torch.rand(8, 1, 3, generator=generator) * 0.01
    seconds = seconds_within_reach(position, velocity, ZERO_G, shoulders)
    assert seconds.shape == (8, CANDIDATE_STARTS)
    for env in (0, 5):
        for k in (0, 3):
            single = seconds_within_reach(position[env, k], velocity[env, k], ZERO_G, shoulders[env, 0])
            assert torch.isclose(single, seconds[env, k])


def test_the_first_catchable_start_is_kept_else_the_longest():
    seconds = torch.tensor([[0.0, MIN_SECONDS_WITHIN_REACH, 3.0], [2.0, 0.5, 3.0], [0.2, 1.0, 0.4]])
    assert first_catchable(seconds).tolist() == [1, 0, 1]


def _rotation(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    cross = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross


def test_a_free_axisymmetric_body_precesses_about_its_angular_momentum_as_it_should():
    inertia = np.array([1.0e-4, 4.0e-4, 4.0e-4])  # a long body (the 3U CubeSat's shape): small inertia about its axis
    axes = _rotation([1, 2, 3], 0.7)  # its principal axes in its own frame
    start = _rotation([0.3, -1, 0.2], 1.1)
    omega = np.array([-0.8, 1.85, 2.23])
    times = np.array([0.25, 0.5, 1.0, 2.0])
    rotations = tumbling_rotations(start, omega, inertia, axes, times)
    world_inertia = lambda rotation: (rotation @ axes) @ np.diag(inertia) @ (rotation @ axes).T  # noqa: E731
    momentum = world_inertia(start) @ omega
    # the closed form for a body symmetric about its first principal axis: that axis turns about the angular
    # momentum at |L| / I_transverse
    symmetry_axis = start @ axes[:, 0]
    for rotation, t in zip(rotations, times):
        np.testing.assert_allclose(rotation.T @ rotation, np.eye(3), atol=1e-9)
        expected = _rotation(momentum, np.linalg.norm(momentum) / inertia[1] * t) @ symmetry_axis
        np.testing.assert_allclose(rotation @ axes[:, 0], expected, atol=1e-4)


def test_spinning_about_a_principal_axis_keeps_turning_about_it():
    axes = np.eye(3)
    rotations = tumbling_rotations(np.eye(3), np.array([0.0, 0.0, 2.0]), np.array([1.0, 2.0, 3.0]), axes, np.array([0.5, 1.5]))
    for rotation, t in zip(rotations, (0.5, 1.5)):
        np.testing.assert_allclose(rotation, _rotation([0, 0, 1], 2.0 * t), atol=1e-9)
