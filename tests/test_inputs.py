"""Every env kwarg of ours is checked for type, finiteness and range before anything is built (the envs'
``check_task_kwargs``, which suites reuse when a file loads), with an error naming the valid choices or range;
the clearance limits follow from the procedural sockets' geometry."""

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import mani_skill_space
from mani_skill_space.envs import TASKS, task_class
from mani_skill_space.envs.base import DEFAULT_CONTROL_MODE, MAX_QPOS_NOISE, supported_control_modes
from mani_skill_space.envs.debris_capture import MAX_DIFFICULTY
from mani_skill_space.kwarg_checks import KwargError
from mani_skill_space.procgen import peg_hole, solar_panel
from mani_skill_space.procgen.peg_hole import PegProfile, bore_fits, make_peg_hole_pair
from mani_skill_space.procgen.solar_panel import make_socket_base, make_solar_layout
from mani_skill_space.suites import SuiteError, load_suite

BAD_KWARGS = [
    ("SampleCollection-v1", dict(robot_init_qpos_noise=float("nan")), "robot_init_qpos_noise must be a finite number >= 0 rad and <= 1.1 rad"),
    ("SampleCollection-v1", dict(robot_init_qpos_noise=10), "<= 1.1 rad"),
    ("SampleCollection-v1", dict(robot_init_qpos_noise=-0.01), ">= 0 rad"),
    ("SampleCollection-v1", dict(robot_init_qpos_noise="0.1"), "got str '0.1'"),
    ("SampleCollection-v1", dict(robot_init_qpos_noise=True), "got bool True"),
    ("SampleCollection-v1", dict(domain=""), "unknown domain ''; valid choices: moon, mars, earth, asteroid"),
    ("SampleCollection-v1", dict(asset_source=""), "unknown asset_source ''; valid choices: procedural, dataset"),
    ("SampleCollection-v1", dict(robot_uids=("panda", "panda")), "valid choices: panda, panda_wristcam"),
    ("SampleCollection-v1", dict(control_mode="pd_magic"), "unknown control_mode 'pd_magic'; valid choices: pd_joint_delta_pos, pd_joint_pos"),
    ("SampleCollection-v1", dict(obs_mode="rgbdd"), "unknown obs_mode 'rgbdd'; valid choices: state, state_dict"),
    ("SampleCollection-v1", dict(reward_mode="shaped"), "unknown reward_mode 'shaped'; valid choices: normalized_dense, dense, sparse, none"),
    ("SampleCollection-v1", dict(reconfiguration_freq=-1), "reconfiguration_freq must be an integer >= 0"),
    ("SampleCollection-v1", dict(reconfiguration_freq=True), "reconfiguration_freq must be an integer >= 0"),
    ("PegInHoleAssembly-v1", dict(clearance=float("nan")), r"valid range \(0, 0.007\] m, got nan"),
    ("PegInHoleAssembly-v1", dict(clearance=0.0075), r"clearance must be positive and at most 0.007 m .*valid range \(0, 0.007\] m"),
    ("PegInHoleAssembly-v1", dict(clearance="a"), "clearance must be positive"),
    ("PegInHoleAssembly-v1", dict(clearance=True), "clearance must be positive"),
    ("PegInHoleAssembly-v1", dict(asset_source="dataset", clearance=0.002), "clearance applies to procedural assets only"),
    ("SolarPanelAssembly-v1", dict(clearance=0.02), r"valid range \(0, 0.001964\] m, got 0.02"),
    ("SolarPanelAssembly-v1", dict(clearance=float("inf")), r"valid range \(0, 0.001964\] m"),
    ("DebrisCapture-v1", dict(difficulty="a"), "difficulty must be a finite number >= 0 and <= 2 .*got str 'a'"),
    ("DebrisCapture-v1", dict(difficulty=100), "difficulty must be a finite number >= 0 and <= 2"),
    ("DebrisCapture-v1", dict(difficulty=True), "got bool True"),
    ("DebrisCapture-v1", dict(difficulty=float("-inf")), "difficulty must be a finite number"),
]


@pytest.mark.parametrize("env_id, kwargs, message", BAD_KWARGS)
def test_bad_kwargs_are_rejected_without_building_a_scene_naming_the_valid_range(env_id, kwargs, message):
    with pytest.raises(KwargError, match=message) as error:
        task_class(env_id).check_task_kwargs(**kwargs)
    assert error.value.kwarg in kwargs


@pytest.mark.parametrize("env_id", TASKS)
def test_the_defaults_and_the_limits_themselves_are_accepted(env_id):
    env_class = task_class(env_id)
    checked = env_class.check_task_kwargs()
    assert checked["domain"] == env_class.DEFAULT_DOMAIN and checked["control_mode"] == DEFAULT_CONTROL_MODE
    assert env_class.check_task_kwargs(robot_init_qpos_noise=MAX_QPOS_NOISE, reconfiguration_freq=0)["robot_init_qpos_noise"] == MAX_QPOS_NOISE
    assert env_class.check_task_kwargs(robot_init_qpos_noise=0)["robot_init_qpos_noise"] == 0.0
    if env_id == "DebrisCapture-v1":
        assert env_class.check_task_kwargs(difficulty=np.float32(MAX_DIFFICULTY))["difficulty"] == MAX_DIFFICULTY
        assert env_class.check_task_kwargs(difficulty=0)["difficulty"] == 0.0


@pytest.mark.parametrize("env_id, limit", [("PegInHoleAssembly-v1", peg_hole.MAX_CLEARANCE), ("SolarPanelAssembly-v1", solar_panel.MAX_CLEARANCE)])
def test_clearance_up_to_the_sockets_limit_is_accepted(env_id, limit):
    assert task_class(env_id).check_task_kwargs(clearance=limit)["clearance"] == limit
    assert task_class(env_id).check_task_kwargs(clearance=1e-4)["clearance"] == 1e-4


def test_a_bad_kwarg_fails_at_make_before_the_scene_is_built():
    with pytest.raises(KwargError, match="robot_init_qpos_noise"):
        gym.make("PegInHoleAssembly-v1", robot_init_qpos_noise=float("nan"))
    with pytest.raises(KwargError, match="difficulty"):
        gym.make("DebrisCapture-v1", difficulty=100)


@pytest.mark.parametrize("env_id", mani_skill_space.ENV_IDS)
def test_control_mode_none_means_our_default_as_no_control_mode_does(env_id):
    """ManiSkill's tools pass control_mode=None when the user gives none; ManiSkill would pick the robot's first
    mode (pd_joint_delta_pos), not the task's."""
    env = gym.make(env_id, control_mode=None, render_backend="none")
    assert env.unwrapped.control_mode == DEFAULT_CONTROL_MODE
    assert env.action_space.shape == (7,)
    env.close()


@pytest.mark.parametrize("robot_uid", ["panda", "panda_wristcam"])
def test_control_modes_read_without_building_the_robot_are_the_built_robots(robot_uid):
    env = gym.make("SampleCollection-v1", robot_uids=robot_uid, render_backend="none")
    agent = env.unwrapped.agent
    assert supported_control_modes(robot_uid) == tuple(agent.supported_control_modes)
    # the noise limit: the rest pose plus the largest noise keeps every arm joint within its limits, a little more does not
    rest = agent.keyframes["rest"].qpos
    limits = agent.robot.get_qlimits()[0].cpu().numpy()
    arm = [i for i in range(len(rest)) if i not in env.unwrapped._gripper_joint_indices.tolist()]
    room = min(min(rest[i] - limits[i, 0], limits[i, 1] - rest[i]) for i in arm)
    assert MAX_QPOS_NOISE <= room < MAX_QPOS_NOISE + 0.01
    env.close()


def test_the_largest_noise_starts_the_arm_within_its_limits():
    env = gym.make("SampleCollection-v1", robot_init_qpos_noise=MAX_QPOS_NOISE, render_backend="none")
    for seed in range(5):
        env.reset(seed=seed)
        robot = env.unwrapped.agent.robot
        qpos, limits = robot.get_qpos()[0], robot.get_qlimits()[0]
        assert bool(((qpos >= limits[:, 0] - 1e-6) & (qpos <= limits[:, 1] + 1e-6)).all())
        assert bool(np.isfinite(env.unwrapped.get_obs().cpu().numpy()).all())
    env.close()


# ---------------------------------------------------------------- clearance limits of the procedural sockets
def _post_wall(profile: PegProfile, clearance: float) -> float:
    """Thinnest wall left between a solar socket's bore and its post's sides."""
    return solar_panel.POST_HALF_WIDTH - float(np.abs(profile.outline(grow=clearance)).max())


def _solar_profiles():
    """The solar profiles' family at its largest radius, on a grid over sides, squash and squash direction."""
    for sides in range(3, solar_panel.MAX_SIDES + 1):
        for aspect in np.linspace(*solar_panel.PROFILE_ASPECT, 9):
            for angle in np.linspace(0.0, np.pi, 73):
                yield PegProfile(sides, False, solar_panel.PROFILE_RADIUS[1], 0.0, 0.0, float(aspect), float(angle))


def test_solar_clearance_limit_is_where_the_thinnest_socket_wall_reaches_the_minimum():
    walls = [_post_wall(p, solar_panel.MAX_CLEARANCE) for p in _solar_profiles()]
    assert min(walls) == pytest.approx(solar_panel.MIN_POST_WALL, abs=1e-6)
    assert min(_post_wall(p, solar_panel.MAX_CLEARANCE + 2e-4) for p in _solar_profiles()) < solar_panel.MIN_POST_WALL - 5e-4


def test_solar_sockets_at_the_clearance_limit_keep_their_walls_and_beyond_are_refused():
    for seed in range(20):
        layout = make_solar_layout(seed, solar_panel.MAX_CLEARANCE)
        assert _post_wall(layout.profile, layout.clearance) >= solar_panel.MIN_POST_WALL - 1e-9
    base = make_socket_base(make_solar_layout(0, solar_panel.MAX_CLEARANCE))
    assert len(base.collision_parts) == 4 * (make_solar_layout(0).profile.sides + 1)  # every bore face walled, and a floor
    with pytest.raises(ValueError, match=r"valid range \(0, 0.001964\] m, got 0.02"):
        make_solar_layout(0, 0.02)


TIGHTEST_PEG_HOLE = dict(profile=PegProfile(3, False, 0.025, 0.08, 0.0, 0.25, 2.509), roll=-peg_hole.MAX_TILT, pitch=-peg_hole.MAX_TILT, yaw=2.265)
"""The tightest pair a search over profile, squash and tilt found: the largest triangle squashed most, tilted to both
limits, in the deepest hole (50 mm); its bore stops fitting at 7.4 mm."""


def _fits(profile, roll, pitch, yaw, clearance):
    rotation = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
    depth = min(0.75 * profile.height, profile.height - peg_hole.FINGER_ROOM)
    return bore_fits(profile, rotation, depth, clearance)


def test_peg_hole_clearance_limit_holds_the_tightest_pair_and_a_millimetre_more_does_not():
    assert _fits(**TIGHTEST_PEG_HOLE, clearance=peg_hole.MAX_CLEARANCE)
    assert not _fits(**TIGHTEST_PEG_HOLE, clearance=peg_hole.MAX_CLEARANCE + 0.001)


def test_peg_hole_pairs_fit_at_the_clearance_limit_and_beyond_are_refused():
    corners = [(r, p) for r in (-peg_hole.MAX_TILT, peg_hole.MAX_TILT) for p in (-peg_hole.MAX_TILT, peg_hole.MAX_TILT)]
    for sides in (3, 4):
        for angle in np.linspace(0.0, np.pi, 7):
            for yaw in np.linspace(-np.pi, np.pi, 7):
                for roll, pitch in corners:
                    profile = PegProfile(sides, False, 0.025, 0.08, 0.0, 0.25, float(angle))
                    assert _fits(profile, roll, pitch, float(yaw), peg_hole.MAX_CLEARANCE)
    for seed in range(10):
        peg, hole = make_peg_hole_pair(seed, peg_hole.MAX_CLEARANCE)
        assert hole.info["clearance"] == peg_hole.MAX_CLEARANCE
    with pytest.raises(ValueError, match=r"valid range \(0, 0.007\] m"):
        make_peg_hole_pair(0, 0.0071)


# ---------------------------------------------------------------- suites check values when they load
SUITE = """name = "values"
episodes = 1

[[configurations]]
env_id = "{env_id}"
kwargs = {{ domain = "{domain}", {key} = {value} }}
"""


@pytest.mark.parametrize(
    "env_id, domain, key, value, message",
    [
        ("SolarPanelAssembly-v1", "moon", "clearance", "0.02", r"valid range \(0, 0.001964\] m"),
        ("SampleCollection-v1", "mars", "robot_init_qpos_noise", "nan", "robot_init_qpos_noise must be a finite number"),
        ("DebrisCapture-v1", "orbit", "difficulty", "true", "got bool True"),
        ("DebrisCapture-v1", "orbit", "difficulty", '"a"', "got str 'a'"),
        ("PegInHoleAssembly-v1", "earth", "control_mode", '"pd_magic"', "unknown control_mode 'pd_magic'"),
    ],
)
def test_suites_check_kwarg_values_when_they_load_and_name_the_line(tmp_path, env_id, domain, key, value, message):
    path = tmp_path / "values.toml"
    path.write_text(SUITE.format(env_id=env_id, domain=domain, key=key, value=value))
    with pytest.raises(SuiteError, match=message) as error:
        load_suite(path)
    assert str(error.value).startswith(f"{path}:6: ")


def test_the_shipped_suites_pass_the_checks():
    for path in sorted((Path(mani_skill_space.__file__).parent / "tasks").glob("*.toml")):
        assert load_suite(path).configurations

