"""The free-flying servicer (``mount="free_flyer"``, orbit): the arm stands on a bus that floats, so arm motions move
and turn it while the total momentum of arm, bus and free objects stays what it was (zero, from rest); it stays put
under a zero action, a heavier bus moves less, the state observation reports it, the base camera rides it, and bad
kwargs name their valid choices."""

import gymnasium as gym
import numpy as np
import pytest
import torch

from mani_skill_space.procgen.servicer import BUS_LINK, DEFAULT_SERVICER_MASS, box_inertia, servicer_urdf

TWO_SECONDS = 40


def make(env_id="PegInHoleAssembly-v1", **kwargs):
    kwargs = dict(domain="orbit", mount="free_flyer", render_backend="none", obs_mode="state_dict", **kwargs)
    return gym.make(env_id, **kwargs)


def _bodies(env):
    """The rigid bodies that may move: every link of the servicer and the task's free objects."""
    u = env.unwrapped
    free = [u.peg] if hasattr(u, "peg") else [u.debris]
    return [link._objs[0] for link in u.agent.robot.links] + [actor._bodies[0] for actor in free]


def _momenta(bodies):
    """Total linear momentum and angular momentum about the world origin, and the sum of the bodies' momentum
    magnitudes (the scale against which the totals are small)."""
    linear, angular, scale = np.zeros(3), np.zeros(3), 0.0
    for body in bodies:
        frame = body.entity_pose * body.cmass_local_pose
        rotation = frame.to_transformation_matrix()[:3, :3]
        velocity, spin = np.asarray(body.linear_velocity, dtype=np.float64), np.asarray(body.angular_velocity, dtype=np.float64)
        momentum = body.mass * velocity
        linear += momentum
        angular += rotation @ np.diag(body.inertia) @ rotation.T @ spin + np.cross(frame.p, momentum)
        scale += np.linalg.norm(momentum)
    return linear, angular, scale


def _swing_arm(env, steps: int, record=None):
    """Joint targets moving the arm about its base and elbow (pd_joint_pos), away from everything else."""
    u = env.unwrapped
    start = u.agent.robot.get_qpos()[0, :8].clone()
    for step in range(steps):
        target = start.clone()
        target[0] += 0.9 * min(1.0, (step + 1) / 20)
        target[3] += 0.4 * min(1.0, (step + 1) / 20)
        env.step(target[None])
        if record is not None:
            record()


def test_momentum_is_conserved_while_the_arm_swings():
    env = make(control_mode="pd_joint_pos")
    env.reset(seed=0)
    u = env.unwrapped
    bodies = _bodies(env)
    readings = []
    _swing_arm(env, TWO_SECONDS, lambda: readings.append(_momenta(bodies)))
    robot = {link._objs[0].entity.name for link in u.agent.robot.links}
    touching = [c for c in u.scene.get_contacts() if not {c.bodies[0].entity.name, c.bodies[1].entity.name} <= robot]
    assert not touching, f"the servicer touched something: {touching}"  # the arm's links may touch each other (internal forces)
    scale = max(r[2] for r in readings)
    assert scale > 1.0  # the arm really moved: over 1 kg m/s of momentum in its links
    assert max(np.linalg.norm(r[0]) for r in readings) < 0.01 * scale
    assert max(np.linalg.norm(r[1]) for r in readings) < 0.01 * scale
    bus = u.agent.robot.links_map[BUS_LINK]
    assert torch.linalg.norm(bus.pose.p[0] - torch.as_tensor(u.mount.frames["arm_mount"][:3, 3], dtype=torch.float32)) > 1e-3  # and moved the bus
    env.close()


def test_the_servicer_stays_at_rest_under_a_zero_action():
    env = make()
    env.reset(seed=1)
    u = env.unwrapped
    start = u.agent.robot.pose.raw_pose.clone()
    for _ in range(TWO_SECONDS):
        obs, *_ = env.step(np.zeros(7, dtype=np.float32))
    torch.testing.assert_close(u.agent.robot.pose.raw_pose, start, atol=1e-4, rtol=0)
    assert torch.linalg.norm(obs["extra"]["servicer_linear_velocity"]) < 1e-3
    env.close()


def test_a_heavier_servicer_moves_less_for_the_same_arm_motion():
    drifts = {}
    for mass in (DEFAULT_SERVICER_MASS, 10 * DEFAULT_SERVICER_MASS):
        env = make(control_mode="pd_joint_pos", servicer_mass=mass)
        env.reset(seed=0)
        u = env.unwrapped
        start = u.agent.robot.pose.p.clone()
        _swing_arm(env, TWO_SECONDS)
        drifts[mass] = torch.linalg.norm(u.agent.robot.pose.p - start).item()
        assert float(u.agent.robot.links_map[BUS_LINK].mass[0]) == mass
        env.close()
    light, heavy = drifts[DEFAULT_SERVICER_MASS], drifts[10 * DEFAULT_SERVICER_MASS]
    assert light > 1e-3 and heavy < 0.5 * light


def test_state_observation_reports_the_servicer_and_the_base_camera_rides_it():
    env = make("DebrisCapture-v1", control_mode="pd_joint_pos")
    obs, _ = env.reset(seed=2)
    extra = obs["extra"]
    assert {"servicer_pos", "servicer_quat", "servicer_linear_velocity", "servicer_angular_velocity"} <= set(extra)
    torch.testing.assert_close(extra["servicer_pos"], torch.zeros(1, 3), atol=1e-5, rtol=0)
    u = env.unwrapped
    (base_camera,) = [config for config in u._default_sensor_configs if config.uid == "base_camera"]
    assert base_camera.mount is u.agent.robot.links_map[BUS_LINK]
    _swing_arm(env, 20)
    obs = u.get_obs()
    assert torch.linalg.norm(obs["extra"]["servicer_pos"]) > 1e-3
    env.close()
    fixed = gym.make("DebrisCapture-v1", domain="orbit", render_backend="none", obs_mode="state_dict")
    obs, _ = fixed.reset(seed=2)
    assert not any(key.startswith("servicer") for key in obs["extra"])  # the station-mounted arm's observation is unchanged
    fixed.close()


@pytest.mark.parametrize(
    "env_id, kwargs, message",
    [
        ("PegInHoleAssembly-v1", dict(domain="moon", mount="free_flyer"), "only in orbit"),
        ("SampleCollection-v1", dict(mount="free_flyer"), "applies to: DebrisCaptureEnv, PegInHoleAssemblyEnv"),
        ("DebrisCapture-v1", dict(domain="orbit", mount="floating"), "valid choices: fixed, free_flyer"),
        ("DebrisCapture-v1", dict(domain="orbit", servicer_mass=100.0), "needs mount='free_flyer'"),
        ("DebrisCapture-v1", dict(domain="orbit", mount="free_flyer", servicer_mass=float("nan")), "servicer_mass must be a number of kg in [10, 100000]"),
    ],
)
def test_bad_mount_kwargs_name_the_valid_choices(env_id, kwargs, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace("[", r"\[")):
        gym.make(env_id, **kwargs)


def test_the_servicer_description_puts_the_arm_on_a_uniform_box():
    arm = '<robot name="arm"><link name="base"><visual><geometry><mesh filename="meshes/base.obj"/></geometry></visual></link><link name="l1"/><joint name="j" type="revolute"><parent link="base"/><child link="l1"/></joint></robot>'
    text = servicer_urdf(arm, "/robots/arm", 200.0, (1.0, 2.0, 3.0))
    assert f'<link name="{BUS_LINK}">' in text and '<mass value="200" />' in text
    assert 'filename="/robots/arm/meshes/base.obj"' in text
    assert f'<parent link="{BUS_LINK}" /><child link="base" />' in text
    np.testing.assert_allclose(box_inertia(12.0, (1.0, 2.0, 3.0)), (13.0, 10.0, 5.0))


def test_the_base_camera_moves_with_the_servicer():
    env = gym.make("DebrisCapture-v1", domain="orbit", mount="free_flyer", obs_mode="rgb", control_mode="pd_joint_pos")
    env.reset(seed=2)
    u = env.unwrapped
    camera, bus = u._sensors["base_camera"].camera, u.agent.robot.links_map[BUS_LINK]

    def camera_in_bus():
        return (bus.pose.inv() * camera.global_pose).raw_pose

    before, camera_before = camera_in_bus(), camera.global_pose.raw_pose.clone()
    _swing_arm(env, 20)
    torch.testing.assert_close(camera_in_bus(), before, atol=1e-4, rtol=0)
    assert torch.linalg.norm(camera.global_pose.p - camera_before[:, :3]) > 1e-3
    env.close()
