import numpy as np

from mani_skill_space.procgen.asset import GPU_CONVEX_VERTEX_LIMIT
from mani_skill_space.procgen.mounts import ARM_MOUNT_HEIGHT, BIN_INNER_HEIGHT, make_rover


def test_rover_frames_put_the_arm_above_the_deck_and_the_bin_behind_it():
    rover = make_rover()
    arm = rover.frames["arm_mount"][:3, 3]
    bin_floor = rover.frames["bin"][:3, 3]
    np.testing.assert_allclose(arm, [0, 0, ARM_MOUNT_HEIGHT])
    assert bin_floor[0] < -0.4 and abs(bin_floor[1]) < 1e-9
    assert rover.info["bin_inner_half_size"][2] * 2 == BIN_INNER_HEIGHT


def test_rover_rests_on_the_ground_and_stays_clear_of_the_sample_area():
    mesh = make_rover().visual_mesh
    assert mesh.bounds[0, 2] == 0.0  # wheels touch the ground
    assert mesh.bounds[1, 0] < 0.3  # nothing reaches the sample area (x >= 0.45)


def test_bin_is_open_and_empty_inside():
    rover = make_rover()
    floor = rover.frames["bin"][:3, 3]
    hx, hy, hz = rover.info["bin_inner_half_size"]
    inner = floor + np.array([0, 0, hz])
    for part in rover.collision_parts:
        lo, hi = part.mesh.bounds
        overlaps = np.all(lo < inner + [hx, hy, hz] - 1e-6) and np.all(hi > inner - [hx, hy, hz] + 1e-6)
        assert not overlaps, "a collision part intrudes into the bin volume"


def test_rover_collision_parts_are_exact_convex_primitives():
    rover = make_rover()
    assert len(rover.collision_parts) == len(rover.visual_parts)
    for visual, collision in zip(rover.visual_parts, rover.collision_parts):
        assert collision.mesh.is_convex
        assert len(collision.mesh.vertices) <= GPU_CONVEX_VERTEX_LIMIT
        np.testing.assert_allclose(visual.mesh.bounds, collision.mesh.bounds)


def test_base_camera_looks_forward_and_down():
    camera = make_rover().frames["base_camera"]
    forward = camera[:3, 0]
    assert forward[0] > 0.5 and forward[2] < -0.3
    np.testing.assert_allclose(camera[:3, :3] @ camera[:3, :3].T, np.eye(3), atol=1e-12)


def test_station_platform_is_the_ground_in_orbit_with_the_arm_and_camera_where_the_rover_has_them():
    from mani_skill_space.procgen.mounts import make_station

    station, rover = make_station(), make_rover()
    for name in ("arm_mount", "base_camera"):
        np.testing.assert_allclose(station.frames[name], rover.frames[name])
    platform = station.collision_parts[0].mesh
    assert platform.bounds[1, 2] == 0.0  # the top of the platform is the surface objects rest on
    assert platform.bounds[0, 0] < -0.3 and platform.bounds[1, 0] > 0.9  # it reaches past the workspace
    assert len(station.visual_parts) > len(station.collision_parts)  # the distant truss and wings are visual only
