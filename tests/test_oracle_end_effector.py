"""The oracles acting in pd_ee_delta_pose: the delta they send is the controller's own target, their motions fit
its per-step limits, and they solve a seed of every task in that mode (physx_cpu, deterministic)."""

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch
from scipy.spatial.transform import Rotation

import mani_skill_space  # noqa: F401
from mani_skill_space.oracles import oracle_for
from mani_skill_space.oracles.base import CATCH_UP_STEPS, CATCH_UP_TOLERANCE, poses_within
from mani_skill_space.oracles.insertion import PegInserter, PegTarget
from mani_skill_space.oracles.peg_in_hole import PEG_IN_HOLE_INSERTION
from mani_skill_space.oracles.end_effector import (
    ROTATION_SPEED_FRACTION,
    TRANSLATION_SPEED_FRACTION,
    EndEffectorDeltaPose,
    arc_round_base,
    arm_delta_controller,
    delta_action_to,
    speed_limit,
)
from mani_skill_space.rollout import run_episode


@pytest.fixture(scope="module")
def ee_env():
    env = gym.make("PegInHoleAssembly-v1", control_mode="pd_ee_delta_pose", render_backend="none")
    env.reset(seed=0)
    yield env
    env.close()


def _controller_target(controller, action):
    """Where the controller puts its end-effector target for ``action`` (its own code path)."""
    processed = controller._preprocess_action(torch.as_tensor(np.asarray(action)[None], dtype=torch.float32))
    target = controller.compute_target_pose(controller.ee_pose_at_base, processed)
    return target.p[0].numpy(), Rotation.from_quat(np.roll(target.q[0].numpy(), -1))


def _offset_target(controller, move, turn):
    now = controller.ee_pose_at_base
    rotation = Rotation.from_rotvec(turn) * Rotation.from_quat(np.roll(now.q[0].numpy().astype(np.float64), -1))
    return now.p[0].numpy().astype(np.float64) + np.asarray(move), rotation


@pytest.mark.parametrize("move, turn", [([0.02, -0.01, 0.03], [0.05, 0.0, 0.0]), ([0.0, 0.04, -0.02], [0.03, -0.04, 0.02]), ([0.0, 0.0, 0.0], [0.0, 0.0, -0.09])])
def test_the_delta_sent_is_the_controllers_target(ee_env, move, turn):
    controller = arm_delta_controller(ee_env.unwrapped)
    position, rotation = _offset_target(controller, move, turn)
    action = delta_action_to(controller, (position, np.roll(rotation.as_quat(), 1)))
    reached_position, reached_rotation = _controller_target(controller, action)
    np.testing.assert_allclose(reached_position, position, atol=1e-6)
    assert (reached_rotation * rotation.inv()).magnitude() < 1e-5


def test_a_target_beyond_the_limits_is_clipped_as_the_controller_clips(ee_env):
    controller = arm_delta_controller(ee_env.unwrapped)
    position, rotation = _offset_target(controller, [0.3, 0.0, -0.05], [0.0, 0.5, 0.0])
    action = delta_action_to(controller, (position, np.roll(rotation.as_quat(), 1)))
    np.testing.assert_allclose(action[:3], [1.0, 0.0, -0.5], atol=1e-6)
    assert np.linalg.norm(action[3:]) == pytest.approx(1.0)
    reached_position, reached_rotation = _controller_target(controller, action)
    now = controller.ee_pose_at_base.p[0].numpy()
    np.testing.assert_allclose(reached_position - now, [0.1, 0.0, -0.05], atol=1e-6)
    assert (reached_rotation * Rotation.from_quat(np.roll(controller.ee_pose_at_base.q[0].numpy(), -1)).inv()).magnitude() == pytest.approx(0.1, abs=1e-5)


def test_the_oracle_refuses_an_env_in_another_control_mode():
    env = gym.make("PegInHoleAssembly-v1", control_mode="pd_joint_pos", render_backend="none")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="pd_ee_delta_pose"):
        EndEffectorDeltaPose(oracle_for("PegInHoleAssembly-v1")).reset(env, 0)
    env.close()


def test_an_unknown_control_mode_names_the_valid_ones():
    with pytest.raises(ValueError, match="pd_joint_pos, pd_ee_delta_pose"):
        oracle_for("PegInHoleAssembly-v1", "pd_joint_delta_pos")


@pytest.mark.parametrize("axis", [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
def test_the_hand_held_at_the_rotation_limit_turns_no_faster_than_the_oracle_plans_turns(ee_env, axis):
    """ROTATION_SPEED_FRACTION rests on this: a turn planned at that share of the limit is at least as fast as the
    hand can turn under the controller, and not much faster (translation, planned at a smaller share, is not the
    bound)."""
    ee_env.reset(seed=0)
    controller = arm_delta_controller(ee_env.unwrapped)  # after the reset, which may rebuild the agent
    planned = speed_limit(controller)[1]
    rotations = []
    for _ in range(12):
        ee_env.step(np.array([0.0, 0.0, 0.0, *axis, 1.0], dtype=np.float32))
        rotations.append(Rotation.from_quat(np.roll(controller.ee_pose_at_base.q[0].numpy().astype(np.float64), -1)))
    per_step = np.array([(a.inv() * b).magnitude() for a, b in zip(rotations[4:], rotations[5:])])  # after the start
    assert np.all(per_step <= planned)
    assert np.all(per_step >= 0.7 * planned)
    assert TRANSLATION_SPEED_FRACTION < ROTATION_SPEED_FRACTION


def test_fast_motions_are_slowed_to_the_speed_limit_and_slow_ones_kept(ee_env):
    oracle = oracle_for("PegInHoleAssembly-v1")
    oracle.reset(ee_env, 0)
    oracle.make_solver(ee_env.unwrapped)
    oracle.tcp_speed_limit = speed_limit(arm_delta_controller(ee_env.unwrapped))
    start = oracle.arm_qpos()
    goal = start + np.array([0.8, -0.4, 0.3, 0.5, -0.6, 0.4, 1.0])
    fast = oracle._timed_path(start, goal)
    slowed = oracle.paced(fast)
    assert len(slowed) > len(fast)
    np.testing.assert_allclose(slowed[-1], goal, atol=1e-9)
    positions, rotations = oracle._tcp_poses(np.concatenate([start[None], slowed]))
    metres, radians = oracle.tcp_speed_limit
    assert np.linalg.norm(np.diff(positions, axis=0), axis=1).max() <= metres * 1.001
    assert max((a.inv() * b).magnitude() for a, b in zip(rotations, rotations[1:])) <= radians * 1.001
    slow = start + np.linspace(0.0, 1.0, 40)[1:, None] * np.full(7, 0.01)
    np.testing.assert_array_equal(oracle.paced(slow), slow)
    # a brisk free-space motion (planned at more than the usual joint accelerations; this one moves the TCP 0.3 m and
    # hardly turns it) may move the TCP free_space_translation_scale times farther a step, for an oracle that asks for
    # it (Solar Panel Assembly's)
    goal = start + np.array([0.0, 0.6, 0.0, 0.0, 0.0, 0.6, 0.0])
    with oracle._speed(1.0, 4.0):
        fast = oracle._timed_path(start, goal)
    slowed = oracle.paced(fast, acceleration=4.0)
    oracle.free_space_translation_scale = 1.5
    np.testing.assert_array_equal(oracle.paced(fast), slowed)
    brisk = oracle.paced(fast, acceleration=4.0)
    np.testing.assert_allclose(brisk[-1], goal, atol=1e-9)
    positions, _ = oracle._tcp_poses(np.concatenate([start[None], brisk]))
    moves = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    assert len(brisk) < len(slowed) and metres * 1.1 < moves.max() <= 1.5 * metres * 1.001


@pytest.mark.parametrize(
    "env_id, domain, asset_source, seed",
    [
        ("SampleCollection-v1", "mars", "dataset", 6000),
        ("SampleCollection-v1", "mars", "procedural", 6000),
        ("PegInHoleAssembly-v1", "moon", "dataset", 6000),
        ("PegInHoleAssembly-v1", "moon", "procedural", 6001),
        # the first feasible plan's pre-grasp, grasp and swing take 137 steps and the push runs out of time; the
        # quickest plan's take 85 (``PegInserter._quickest_plan``)
        ("PegInHoleAssembly-v1", "moon", "procedural", 60028),
        # the joint-space swing over the hole takes 100 steps and the push runs out of time; the straight swing 40
        # (``PegInserter._swing_over``)
        ("PegInHoleAssembly-v1", "moon", "procedural", 6046),
        # the screw motions' helices take the push past the episode's end; the hand's quicker lines (the lift, 19 steps
        # as a screw and 9 as a line on a traced seed) have the peg in at step 121
        ("PegInHoleAssembly-v1", "moon", "procedural", 60035),
        ("DebrisCapture-v1", "orbit", "dataset", 6002),
        ("DebrisCapture-v1", "orbit", "procedural", 6000),
    ],
)
def test_the_oracle_solves_every_task_in_ee_delta_pose(env_id, domain, asset_source, seed):
    env = gym.make(env_id, domain=domain, asset_source=asset_source, control_mode="pd_ee_delta_pose", render_backend="none")
    result = run_episode(env, oracle_for(env_id, "pd_ee_delta_pose"), seed)
    assert result.success_once and result.success_at_end, (env_id, domain, asset_source, seed, result.failure)
    env.close()


def _peg_oracle_in_ee(ee_env) -> EndEffectorDeltaPose:
    """The Peg-in-Hole oracle acting in pd_ee_delta_pose on seed 0, its planner ready."""
    ee_env.unwrapped.reset(seed=0)
    policy = EndEffectorDeltaPose(oracle_for("PegInHoleAssembly-v1"))
    policy.reset(ee_env, 0)
    policy.oracle.make_solver(ee_env.unwrapped)
    return policy


def _send(ee_env, policy, target) -> None:
    """Step ``ee_env`` with the arm joint ``target`` as ``policy`` sends it: the TCP pose it puts the hand in, as a
    delta (the gripper open)."""
    arm = delta_action_to(policy.controller, policy.tcp_pose_at_base(target))
    ee_env.step(np.concatenate([arm, [1.0]]).astype(np.float32))


def _joints_after_sending(ee_env, policy, actions) -> np.ndarray:
    """The arm's joints after the oracle's joint-target ``actions`` are sent as ``policy`` sends them, the last held 10
    more steps."""
    targets = [action[:-1] for action in actions]
    for target in targets + targets[-1:] * 10:
        _send(ee_env, policy, target)
    return policy.oracle.arm_qpos().copy()


def test_where_the_controller_leaves_the_arm_after_a_joint_move_is_predicted(ee_env):
    """A TCP controller follows the hand's poses along a joint move but settles the arm's redundancy its own way: the
    oracle predicts the joints it ends in (``Oracle.joint_move_end``), which are not the move's goal."""
    env = ee_env.unwrapped
    policy = _peg_oracle_in_ee(ee_env)
    oracle = policy.oracle
    start = oracle.arm_qpos()
    goal = start + np.array([0.9, 0.3, -0.9, 0.3, 0.9, 0.5, -0.6])
    predicted = oracle.joint_move_end(start, goal)
    reached = _joints_after_sending(ee_env, policy, oracle.joint_move(goal, "swing"))
    assert np.abs(reached - goal).max() > 0.3  # the arm did not end at the move's goal...
    np.testing.assert_allclose(reached, predicted, atol=0.05)  # ...but where the prediction said
    np.testing.assert_allclose(oracle._tcp_poses([reached])[0], oracle._tcp_poses([goal])[0], atol=0.005)
    env.reset(seed=0)


def test_where_the_controller_leaves_the_arm_after_a_planned_motion_is_predicted(ee_env):
    """A plan checked before moving chains each motion from where the one before leaves the arm. Under a TCP controller
    that is where its IK leaves it along the motion (``Oracle.motion_end``, ``straight_motion_end``, ``screw_end``:
    ``Oracle._followed_end``), not the planned path's last joints: traced on Solar Panel Assembly (procedural, Moon,
    seed 6000), a pre-grasp motion planned to end with the first joint at -1.91 rad ended at -0.07, and the grasp
    planned from the planned end stalled 44 mm short of the peg. Here ``screw_to``'s motion (mplib has no screw there,
    so a joint-space move) is planned to end 0.9 rad from where the controller takes the arm; a controller that would
    stall leaves no plan."""
    env = ee_env.unwrapped
    policy = _peg_oracle_in_ee(ee_env)
    oracle = policy.oracle
    start, hand = oracle.arm_qpos(), oracle.tcp_pose()
    turn = Rotation.from_rotvec([-0.23, 0.07, -0.68])
    goal = sapien.Pose(hand.p + [-0.3, -0.11, -0.27], _wxyz(turn * Rotation.from_quat(np.roll(hand.q, -1))))
    planned_end = oracle._planned_motion(start, goal, 1.0)[-1][: len(start)]
    predicted = oracle.motion_end(start, goal)
    reached = _joints_after_sending(ee_env, policy, oracle.screw_to(goal, "move"))
    assert np.abs(reached - planned_end).max() > 0.5  # the arm did not end where the path did...
    np.testing.assert_allclose(reached, predicted, atol=0.1)  # ...but where the prediction said
    oracle.arm_follower = lambda start, path: None  # a controller that stalls short of the goal
    assert oracle.motion_end(start, goal) is None
    env.reset(seed=0)


def test_the_hand_catches_up_with_a_brisk_motion_before_the_next(ee_env):
    """The hand lags its targets by about two control steps, and the motion after a brisk one starts from where the arm
    is (traced on Solar Panel Assembly, procedural, Moon, seed 6021: the straight way in to a grasp, planned from the
    pre-grasp pose, ran into the peg from 9 cm short of it). ``Oracle.catch_up`` holds the last target until the hand is
    there, and holds nothing once it is, or in joint control."""
    policy = _peg_oracle_in_ee(ee_env)
    oracle = policy.oracle
    hand = oracle.tcp_pose()
    goal = sapien.Pose(hand.p + [-0.3, -0.11, -0.2], hand.q)

    def steps_sent(actions) -> int:
        sent = 0
        for action in actions:
            oracle.last_action = action
            _send(ee_env, policy, action[:-1])
            sent += 1
        return sent

    def hand_within_tolerance() -> bool:
        return poses_within((oracle.tcp_pose().p, oracle.tcp_pose().q), (goal.p, goal.q), CATCH_UP_TOLERANCE)

    steps_sent(oracle.screw_to(goal, "move", acceleration=2.0))
    assert not hand_within_tolerance()  # the motion's targets have all been sent, the hand is not there yet
    assert 0 < steps_sent(oracle.catch_up(goal)) <= CATCH_UP_STEPS
    assert hand_within_tolerance()
    assert steps_sent(oracle.catch_up(goal)) == 0
    oracle.tcp_speed_limit = None  # joint control
    assert steps_sent(oracle.catch_up(sapien.Pose(goal.p + [0.1, 0.0, 0.0], goal.q))) == 0
    ee_env.unwrapped.reset(seed=0)


def test_a_servo_ends_before_the_first_step_its_condition_holds_for(ee_env):
    """``Oracle.servo``'s ``until``: a push under a TCP controller ends once its schedule has run and the peg is seated
    (``insertion.SEATED_TIP_HEIGHT``), not after all its extra steps."""
    oracle = _peg_oracle_in_ee(ee_env).oracle
    hand = oracle.tcp_pose()
    assert len(list(oracle.servo(lambda step: hand, 10, "hold", until=lambda step: step >= 3))) == 3
    assert len(list(oracle.servo(lambda step: hand, 10, "hold", until=lambda step: False))) == 10
    assert len(list(oracle.servo(lambda step: hand, 10, "hold"))) == 10


def test_the_hand_goes_over_the_top_up_across_and_down(ee_env):
    """``Oracle.over_the_top_path``: the hand straight up to the oracle's ``via_height``, straight across at it, straight
    down to the goal, each line the controller's own IK within the speed limit; nothing where the oracle has no
    ``via_height``."""
    policy = _peg_oracle_in_ee(ee_env)
    oracle = policy.oracle
    start, hand = oracle.arm_qpos(), oracle.tcp_pose()
    goal = sapien.Pose(hand.p + [-0.15, 0.2, -0.05], hand.q)
    assert oracle.over_the_top_path(start, goal) is None  # the peg's oracle moves in no such paths
    oracle.straight_lines_under_tcp_control, oracle.via_height = True, float(hand.p[2]) + 0.15
    path = oracle.over_the_top_path(start, goal)
    positions, _ = oracle._tcp_poses(np.concatenate([start[None], path]))
    top = np.isclose(positions[:, 2], oracle.via_height, atol=0.005)
    first, last = np.flatnonzero(top)[[0, -1]]
    assert np.all(np.diff(positions[: first + 1, 2]) > -1e-4)  # up...
    np.testing.assert_allclose(positions[first, :2], hand.p[:2], atol=0.005)
    assert np.all(top[first : last + 1])  # ...across at the height...
    np.testing.assert_allclose(positions[last, :2], goal.p[:2], atol=0.005)
    assert np.all(np.diff(positions[last:, 2]) < 1e-4)  # ...and down
    np.testing.assert_allclose(positions[-1], goal.p, atol=0.005)
    metres, _ = oracle.tcp_step_limit()
    assert np.linalg.norm(np.diff(positions, axis=0), axis=1).max() <= metres * 1.05


def test_the_solar_panel_oracle_assembles_within_the_episode_in_ee_delta_pose():
    """Solar Panel Assembly's four pegs and panel fit its 1000 steps in this mode with the hand moving in straight lines
    (``Oracle.straight_lines_under_tcp_control``; with joint-space swings seed 0 filled three sockets, and before
    ``Oracle.joint_move_end`` one: the second push stalled at a joint limit)."""
    env = gym.make("SolarPanelAssembly-v1", domain="moon", asset_source="dataset", control_mode="pd_ee_delta_pose", render_backend="none")
    result = run_episode(env, oracle_for("SolarPanelAssembly-v1", "pd_ee_delta_pose"), 0)
    assert result.success_once and result.success_at_end, (result.stage, result.failure)
    env.close()


def test_a_straight_line_of_the_hand_is_followed_within_the_speed_limit(ee_env):
    """``Oracle.straight_line_path`` (the controller's IK stepped along the line, ``EndEffectorDeltaPose.line_path``): the
    hand moves evenly along the segment and turns evenly about one axis, no faster than the oracle's limits, and ends at
    the goal; a goal out of the arm's reach has no such path."""
    policy = _peg_oracle_in_ee(ee_env)
    oracle = policy.oracle
    start, hand = oracle.arm_qpos(), oracle.tcp_pose()
    turn = Rotation.from_rotvec([0.3, -0.4, 0.5])
    goal = sapien.Pose(hand.p + [0.05, -0.08, -0.06], np.roll((turn * Rotation.from_quat(np.roll(hand.q, -1))).as_quat(), 1))
    assert oracle.straight_line_path(start, goal) is None  # the single peg's oracle does not move in straight lines
    oracle.straight_lines_under_tcp_control = True
    path = oracle.straight_line_path(start, goal)
    assert path is not None
    positions, rotations = oracle._tcp_poses(np.concatenate([start[None], path]))
    metres, radians = oracle.tcp_speed_limit
    steps = int(np.ceil(max(0.11 / metres, turn.magnitude() / radians)))
    assert len(path) == pytest.approx(steps, abs=1)
    assert np.linalg.norm(np.diff(positions, axis=0), axis=1).max() <= metres * 1.05
    assert max((a.inv() * b).magnitude() for a, b in zip(rotations, rotations[1:])) <= radians * 1.05
    along = (positions - hand.p) @ (goal.p - hand.p) / np.linalg.norm(goal.p - hand.p) ** 2
    off_line = np.linalg.norm(positions - hand.p - along[:, None] * (goal.p - hand.p), axis=1)
    assert off_line.max() < 0.002 and np.all(np.diff(along) > 0)
    np.testing.assert_allclose(positions[-1], goal.p, atol=0.005)
    assert (rotations[-1].inv() * Rotation.from_quat(np.roll(goal.q, -1))).magnitude() < 0.05
    assert oracle.straight_line_path(start, sapien.Pose(hand.p + [1.5, 0.0, 0.0], hand.q)) is None


def _wxyz(rotation):
    return np.roll(rotation.as_quat(), 1)


@pytest.mark.parametrize("way", [1, -1])
@pytest.mark.parametrize("carried", [False, True])
def test_an_arc_round_the_base_sweeps_the_way_asked_within_the_limits(way, carried):
    """``arc_round_base``: from behind the base (azimuth 170 deg) to in front of it (-30 deg), the hand's azimuth moves
    evenly the way asked (+1 anticlockwise, 160 deg; -1 clockwise, 200 deg), its distance from the axis and
    height evenly, each step within the limits, and the last pose is the goal; a carried hand keeps its orientation
    relative to the sweep, plus an even turn for the rest."""
    start_rotation, goal_rotation = Rotation.from_euler("xyz", [np.pi, 0.0, 1.2]), Rotation.from_euler("xyz", [np.pi - 0.5, 0.4, -0.3])
    start = (np.array([0.35 * np.cos(np.radians(170)), 0.35 * np.sin(np.radians(170)), 0.35]), _wxyz(start_rotation))
    goal = (np.array([0.55 * np.cos(np.radians(-30)), 0.55 * np.sin(np.radians(-30)), 0.3]), _wxyz(goal_rotation))
    limit = (0.05, 0.05)
    hands = arc_round_base(start, goal, way, carried, limit)
    positions = np.stack([start[0]] + [p for p, _ in hands])
    rotations = Rotation.from_quat(np.stack([np.roll(start[1], -1)] + [np.roll(q, -1) for _, q in hands]))
    azimuths = np.unwrap(np.arctan2(positions[:, 1], positions[:, 0]))
    sweep = np.radians(160.0) if way > 0 else np.radians(-200.0)
    np.testing.assert_allclose(np.diff(azimuths), sweep / len(hands), atol=1e-9)
    np.testing.assert_allclose(np.diff(np.hypot(positions[:, 0], positions[:, 1])), 0.2 / len(hands), atol=1e-9)
    np.testing.assert_allclose(np.diff(positions[:, 2]), -0.05 / len(hands), atol=1e-9)
    assert np.linalg.norm(np.diff(positions, axis=0), axis=1).max() <= limit[0] + 1e-9
    turns = np.array([(a.inv() * b).magnitude() for a, b in zip(rotations[:-1], rotations[1:])])
    assert turns.max() <= limit[1] + 1e-9
    np.testing.assert_allclose(positions[-1], goal[0], atol=1e-9)
    assert (rotations[-1].inv() * goal_rotation).magnitude() < 1e-6
    relative = Rotation.from_euler("z", -azimuths[:, None]) * rotations  # the hand's orientation in the sweep's frame
    # carried: a turn about one axis on top of the sweep; else a turn about one axis of its own
    assert _about_one_axis(relative) == carried
    assert _about_one_axis(rotations) != carried


def _about_one_axis(rotations) -> bool:
    axes = (rotations[0].inv() * rotations[1:]).as_rotvec()
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    return bool(np.allclose(axes, axes[0], atol=1e-6))


def test_an_arc_at_the_same_azimuth_takes_no_full_turn():
    """A lift (start and goal at the same azimuth) is a short path either way round, not a full circle one way."""
    start = (np.array([0.4, 0.1, 0.2]), _wxyz(Rotation.from_euler("x", np.pi)))
    goal = (np.array([0.4, 0.1 - 1e-13, 0.5]), start[1])  # the same azimuth, up to rounding
    for way in (1, -1):
        hands = arc_round_base(start, goal, way, True, (0.05, 0.05))
        assert len(hands) == 6
        np.testing.assert_allclose([p[:2] for p, _ in hands], np.tile([0.4, 0.1], (6, 1)), atol=1e-12)


def test_an_arc_round_the_base_asks_for_a_way_round():
    hand = (np.array([0.3, 0.0, 0.3]), np.array([1.0, 0.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="way must be"):
        arc_round_base(hand, hand, 0, False, (0.05, 0.05))


def test_an_arm_the_controller_left_elsewhere_goes_back_to_where_it_started_to_plan_a_grasp(ee_env):
    """``PegInserter._goes_back_to_the_start``: under a TCP controller an arm away from where it started the episode is
    sent back there, where a plan exists from where the controller leaves it; not in joint control, nor an arm that
    is there already."""
    policy = _peg_oracle_in_ee(ee_env)
    oracle = policy.oracle
    inserter = PegInserter(oracle, PEG_IN_HOLE_INSERTION)
    target = PegTarget.of(ee_env.unwrapped, ee_env.unwrapped.peg, 0)
    end = inserter._end_toward_arm(target)
    assert not inserter._goes_back_to_the_start(target, end, [])  # there already

    elsewhere = oracle.start_qpos + np.array([0.5, 0.0, 0.0, 0.0, 0.0, 0.4, 0.0])
    for action in oracle.joint_move(elsewhere, "away"):
        _send(ee_env, policy, action[:-1])
    assert np.max(np.abs(oracle.arm_qpos() - oracle.start_qpos)) > 0.3
    assert inserter._goes_back_to_the_start(target, end, [])
    for action in oracle.joint_move(oracle.start_qpos, "back to the start"):
        _send(ee_env, policy, action[:-1])
    assert np.max(np.abs(oracle.arm_qpos() - oracle.start_qpos)) < 0.1

    follower, oracle.arm_follower = oracle.arm_follower, None  # joint control
    try:
        for action in oracle.joint_move(elsewhere, "away"):
            _send(ee_env, policy, action[:-1])
        assert not inserter._goes_back_to_the_start(target, end, [])
    finally:
        oracle.arm_follower = follower
        ee_env.unwrapped.reset(seed=0)
