"""Factor-shift kwargs: each moves its one factor, is checked, and is off by default."""

import math

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch

import mani_skill_space  # noqa: F401
from mani_skill_space.envs import task_class
from mani_skill_space.factors import camera_offsets, jittered_camera_frames
from mani_skill_space.kwarg_checks import KwargError
from mani_skill_space.procgen.asset import look_at


def _sample_component(env):
    return env.unwrapped.sample._objs[0].find_component_by_type(sapien.physx.PhysxRigidDynamicComponent)


def _vertices(env) -> np.ndarray:
    return np.concatenate([shape.get_vertices() * shape.get_scale() for shape in _sample_component(env).collision_shapes])


@pytest.fixture(scope="module")
def reset_with(make_sample_collection):
    def _reset_with(**kwargs):
        env = make_sample_collection(**kwargs)
        env.reset(seed=11)
        return env

    return _reset_with


def test_defaults_change_nothing_and_object_shifts_change_only_the_object(reset_with):
    plain = reset_with()
    scaled = reset_with(object_scale=1.2)
    extent = lambda env: np.ptp(_vertices(env), axis=0)  # noqa: E731  (PhysX cooks the hulls anew: compare sizes)
    np.testing.assert_allclose(extent(scaled), 1.2 * extent(plain), rtol=2e-3)
    heavy = reset_with(object_mass_scale=3.0)
    assert math.isclose(_sample_component(heavy).mass, 3.0 * _sample_component(plain).mass, rel_tol=1e-5)
    slippery = reset_with(object_friction=0.3)
    materials = [shape.physical_material for shape in _sample_component(slippery).collision_shapes]
    assert all(math.isclose(m.static_friction, 0.3, rel_tol=1e-6) and math.isclose(m.dynamic_friction, 0.3, rel_tol=1e-6) for m in materials)
    assert all(shape.physical_material.static_friction == 1.0 for shape in _sample_component(plain).collision_shapes)


def test_gravity_and_sun_shifts(reset_with):
    plain = reset_with()
    lighter = reset_with(gravity_scale=0.8)
    np.testing.assert_allclose(lighter.unwrapped.sim_config.scene_config.gravity, 0.8 * np.asarray(plain.unwrapped.sim_config.scene_config.gravity))
    behind = reset_with(sun_pitch_range=(-75.0, -10.0))
    # the light travels along -z turned by the pitch about y: a positive pitch gives it a negative x component
    assert behind.unwrapped._sun_directions[0][0] > 0 and plain.unwrapped._sun_directions[0][0] <= 0


def test_camera_jitter_is_per_env_bounded_and_deterministic():
    assert camera_offsets(np.array([1, 2]), 0.0) is None
    offsets = camera_offsets(np.array([1, 2, 1]), 0.05)
    assert offsets.shape == (3, 2, 3) and np.abs(offsets).max() <= 0.05
    np.testing.assert_array_equal(offsets[0], offsets[2])
    assert not np.allclose(offsets[0], offsets[1])
    frame = look_at((0.3, 0.2, 0.6), (-0.2, 0.0, 0.1))
    unmoved = jittered_camera_frames(frame, np.zeros((2, 2, 3)))
    np.testing.assert_allclose(unmoved[1], frame, atol=1e-12)
    moved = jittered_camera_frames(frame, offsets)
    np.testing.assert_allclose(moved[:, :3, 3], frame[:3, 3] + offsets[:, 0], atol=1e-12)


def test_camera_jitter_moves_the_base_camera_per_env():
    env = gym.make("SampleCollection-v1", obs_mode="rgbd", camera_jitter=0.05)
    try:
        env.reset(seed=3)
        pose = env.unwrapped.scene.sensors["base_camera"].camera.global_pose
        nominal = sapien.Pose(env.unwrapped.mount.frames["base_camera"])
        assert 0 < torch.linalg.norm(pose.p[0] - torch.as_tensor(nominal.p)).item() <= 0.05 * math.sqrt(3) + 1e-6
    finally:
        env.close()


@pytest.mark.parametrize(
    "env_id, kwargs, message",
    [
        ("PegInHoleAssembly-v1", dict(object_scale=1.2), "no object_scale: its objects must fit their sockets; tasks with it: SampleCollectionEnv, DebrisCaptureEnv"),
        ("SampleCollection-v1", dict(object_scale=3.0), "object_scale must be a finite number >= 0.5 and <= 2"),
        ("SampleCollection-v1", dict(object_mass_scale=float("nan")), "object_mass_scale must be a finite number"),
        ("SampleCollection-v1", dict(object_friction="low"), "object_friction must be a finite number >= 0 and <= 2"),
        ("SampleCollection-v1", dict(gravity_scale=-1.0), "gravity_scale must be a finite number >= 0 and <= 3"),
        ("SampleCollection-v1", dict(camera_jitter=0.5), "camera_jitter must be a finite number >= 0 m and <= 0.2 m"),
        ("SampleCollection-v1", dict(sun_pitch_range=(10.0,)), r"sun_pitch_range must be a \(low, high\) pair"),
        ("SampleCollection-v1", dict(sun_pitch_range=(20.0, 10.0)), "low <= high"),
        ("SampleCollection-v1", dict(sun_pitch_range=(0.0, 120.0)), "sun_pitch_range must be a finite number >= -90 degrees and <= 90 degrees"),
    ],
)
def test_bad_factor_kwargs_name_the_valid_range(env_id, kwargs, message):
    with pytest.raises(KwargError, match=message):
        task_class(env_id).check_task_kwargs(**kwargs)
