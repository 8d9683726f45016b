"""The oracles acting in ``pd_ee_delta_pose`` (ManiSkill's default Panda controller, and ours), so that their
demonstrations are recorded natively in the control mode learners use, with no conversion afterwards.

An oracle plans joint targets. At every control step ``EndEffectorDeltaPose`` takes the oracle's joint target,
computes the TCP pose it puts the hand in (forward kinematics on the robot's own model) and sends the end-effector
delta that moves the TCP from where it is now to that pose. The controller adds the delta to the TCP's current pose
and solves IK from the current joints, so its joint target is the oracle's (up to the arm's redundancy), the loop is
closed at every step and nothing is stretched in time: a timed motion such as a debris capture keeps its timing,
which ManiSkill's conversion of recorded joint actions (extra steps where the delta would be clipped) cannot.

The arm's redundancy is the controller's to settle: its IK, re-solved from the joints as they are at every step,
takes the hand along the poses of a long joint-space swing but can end it with the elbow and wrist a radian or more
from the swing's goal. The oracle plans what comes after a swing from where the controller will leave the arm
(``EndEffectorDeltaPose.followed_end``, the controller's own IK stepped along the swing; ``Oracle.joint_move_end``).
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import sapien
import torch
from mani_skill.agents.controllers.pd_ee_pose import PDEEPoseController
from mani_skill.utils.geometry.rotation_conversions import matrix_to_euler_angles, quaternion_to_matrix
from mani_skill.utils.gym_utils import inv_scale_action
from mani_skill.utils.structs.pose import Pose
from scipy.spatial.transform import Rotation, Slerp

from mani_skill_space.oracles.base import Oracle, poses_within
from mani_skill_space.policy import WrapsOracle

CONTROL_MODE = "pd_ee_delta_pose"
DELTA_FRAME = "root_translation:root_aligned_body_rotation"
TRANSLATION_SPEED_FRACTION = 1.0 / 3.0
"""Share of the controller's per-step translation limit the oracle's TCP may move in a step. The delta sent is the
step's motion plus the arm's lag behind its previous target, and the Panda's joint drives (stiffness 1000, damping
100) lag 0.1 s, two control steps, behind a target moving at a steady speed: step and lag fit within the limit
together at a third of it."""

ROTATION_SPEED_FRACTION = 1.0 / 2.0
"""Share of the controller's per-step rotation limit the oracle's TCP may turn in a step. Turning is what bounds
this controller: held at its rotation limit, the hand turns 0.039 rad a step (0.39 of the limit), where held at its
translation limit it moves 0.045-0.056 m (half of it). A plan turning at half the limit runs a little ahead of a
long turn; the lag that builds up is made up by the next motion, which is planned from where the arm is. At a third,
as for translation, the long turns of the swings over a procedural peg's hole ran out of the episode's time: on
Moon seeds 60000-60059 32 of 60 pegs were inserted at a third, 37 at 0.4, 40 at a half and 39 at 0.6."""

FOLLOW_TOLERANCE = (0.005, 0.05)
"""(m, rad): how close to a motion's last pose the controller must bring the hand for the motion to count as followed
(``EndEffectorDeltaPose.followed_end``)."""


class EndEffectorDeltaPose(WrapsOracle):
    """``oracle`` acting in ``pd_ee_delta_pose`` (see the module docstring)."""

    control_mode = CONTROL_MODE

    def __init__(self, oracle: Oracle):
        self.oracle = oracle

    def reset(self, env, seed: int) -> None:
        self.controller = arm_delta_controller(env.unwrapped)
        self.model = self.controller.articulation.create_pinocchio_model()
        self.oracle.tcp_speed_limit = speed_limit(self.controller)
        self.oracle.arm_follower = self.followed_end
        self.oracle.line_follower = self.line_path
        self.oracle.arc_follower = self.arc_path
        self.oracle.reset(env, seed)

    def act(self, obs) -> np.ndarray:
        joint_action = self.oracle.act(obs)
        arm_target, gripper = joint_action[:-1], joint_action[-1:]
        arm_action = delta_action_to(self.controller, self.tcp_pose_at_base(arm_target))
        return np.concatenate([arm_action, gripper]).astype(np.float32)

    def followed_end(self, start: np.ndarray, path: np.ndarray) -> Optional[np.ndarray]:
        """The arm joints in which the controller leaves the arm when ``act`` is given the joint targets ``path`` (one
        per step) from ``start``, the arm taken to keep up with its targets (``_followed``); None if the hand does not
        end at the path's last pose: the motion stalls short of it."""
        followed = self._followed(start, [self.tcp_pose_at_base(target) for target in path])
        return None if followed is None else followed[-1]

    def line_path(self, start: np.ndarray, goal: sapien.Pose, limit: tuple[float, float]) -> Optional[np.ndarray]:
        """Arm joint targets, one per control step, that take the hand in a straight line from where ``start`` puts it
        to ``goal`` (world frame): its position moved and its orientation turned (about one axis) evenly, as fast as
        ``limit`` (metres, radians per step) allows, each target the controller's
        own IK (``_followed``); None where the controller stalls short of ``goal``."""
        base_goal = self.controller.articulation.pose.sp.inv() * goal
        position, quaternion = self.tcp_pose_at_base(start)
        rotations = Rotation.from_quat(np.stack([np.roll(quaternion, -1), np.roll(base_goal.q, -1)]))  # wxyz -> xyzw
        metres, radians = limit
        distance, turn = np.linalg.norm(base_goal.p - position), (rotations[0].inv() * rotations[1]).magnitude()
        fractions = np.linspace(0.0, 1.0, max(1, int(np.ceil(max(distance / metres, turn / radians)))) + 1)[1:]
        turned = Slerp([0.0, 1.0], rotations)(fractions).as_quat()
        hands = [(position + t * (base_goal.p - position), np.roll(q, 1)) for t, q in zip(fractions, turned)]
        return self._followed(start, hands)

    def arc_path(self, start: np.ndarray, goal: sapien.Pose, limit: tuple[float, float], way: int, carried: bool) -> Optional[np.ndarray]:
        """Arm joint targets, one per control step, that take the hand round the arm's base from where ``start`` puts it
        to ``goal`` (world frame), ``way`` round (+1: anticlockwise seen from above, -1: clockwise), its orientation
        ``carried`` round with the sweep or not (``arc_round_base``), within ``limit`` (metres, radians per step), each
        target the controller's own IK (``_followed``); None where the controller stalls short of ``goal``."""
        base_goal = self.controller.articulation.pose.sp.inv() * goal
        hands = arc_round_base(self.tcp_pose_at_base(start), (base_goal.p, base_goal.q), way, carried, limit)
        return self._followed(start, hands)

    def _followed(self, start: np.ndarray, hands: list) -> Optional[np.ndarray]:
        """The arm joints, one per step, in which the controller puts the arm when sent hand poses ``hands`` (position,
        wxyz quaternion in the base frame) from ``start``, the arm taken to keep up: at each step the controller's own IK
        (CPU, ``compute_ik``), from the joints reached, the joints stopped at their limits (the IK does not know them;
        where it fails, the controller holds the arm for that step). None if the hand does not end at the last pose
        (``FOLLOW_TOLERANCE``)."""
        articulation = self.controller.articulation
        arm = self.controller.active_joint_indices
        low, high = articulation.get_qlimits()[0, arm].T
        qpos = articulation.get_qpos().clone()
        qpos[0, arm] = torch.as_tensor(np.asarray(start), dtype=qpos.dtype)
        followed = []
        for hand in hands:
            solved = self.controller.kinematics.compute_ik(Pose.create_from_pq(*hand), q0=qpos)
            if solved is not None:
                qpos[0, arm] = torch.clamp(solved[0].to(qpos.dtype), low, high)
            followed.append(qpos[0, arm].cpu().numpy().astype(np.float64))
        return np.stack(followed) if poses_within(self.tcp_pose_at_base(followed[-1]), hands[-1], FOLLOW_TOLERANCE) else None

    def tcp_pose_at_base(self, arm_qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(position, wxyz quaternion) of the controller's end-effector link, in the robot's base frame, with the arm
        joints at ``arm_qpos`` and the other joints (the fingers) where they are."""
        qpos = self.controller.articulation.get_qpos()[0].cpu().numpy().copy()
        qpos[self.controller.active_joint_indices.cpu().numpy()] = arm_qpos
        self.model.compute_forward_kinematics(qpos)
        pose = self.model.get_link_pose(self.controller.ee_link.index)
        return np.asarray(pose.p), np.asarray(pose.q)


def arc_round_base(start: tuple[np.ndarray, np.ndarray], goal: tuple[np.ndarray, np.ndarray], way: int, carried: bool, limit: tuple[float, float]) -> list:
    """Hand poses ((position, wxyz quaternion) in the arm's base frame), one per control step, from ``start`` round the
    base's vertical axis to ``goal``: the azimuth swept ``way`` round (+1 anticlockwise seen from above, -1 clockwise),
    the distance from the axis and the height changed evenly; the hand turned evenly about one axis from its start to
    its goal orientation, on top of being turned with the sweep as the arm's first joint carries it where ``carried``;
    as many steps as ``limit`` (metres, radians per step) asks for the turn and for the arc where it is widest."""
    if way not in (1, -1):
        raise ValueError(f"way must be +1 or -1, got {way!r}")
    (position, quaternion), (goal_position, goal_quaternion) = start, goal
    azimuth = np.arctan2(position[1], position[0])
    ahead = (np.arctan2(goal_position[1], goal_position[0]) - azimuth) % (2.0 * np.pi)  # anticlockwise, in [0, 2 pi)
    if min(ahead, 2.0 * np.pi - ahead) < 1e-9:  # the same azimuth (a lift): no full turn either way round
        ahead = 0.0
    sweep = ahead if way > 0 or ahead == 0.0 else ahead - 2.0 * np.pi
    radius, goal_radius = np.hypot(*position[:2]), np.hypot(*goal_position[:2])

    def positions(fractions: np.ndarray) -> np.ndarray:
        angles, radii = azimuth + sweep * fractions, radius + (goal_radius - radius) * fractions
        heights = position[2] + (goal_position[2] - position[2]) * fractions
        return np.stack([radii * np.cos(angles), radii * np.sin(angles), heights], axis=1)

    carry = sweep if carried else 0.0
    turned = Rotation.from_quat(np.stack([np.roll(quaternion, -1), np.roll(goal_quaternion, -1)]))  # wxyz -> xyzw
    rest = Rotation.concatenate([turned[0], Rotation.from_euler("z", -carry) * turned[1]])  # the goal turned back by the carry
    fastest = np.linalg.norm([max(radius, goal_radius) * sweep, goal_radius - radius, goal_position[2] - position[2]])  # m per unit of the sweep's progress, at its widest
    turn = abs(carry) + (rest[0].inv() * rest[1]).magnitude()
    metres, radians = limit
    fractions = np.linspace(0.0, 1.0, max(1, int(np.ceil(max(fastest / metres, turn / radians)))) + 1)[1:]
    rotations = Rotation.from_euler("z", (carry * fractions)[:, None]) * Slerp([0.0, 1.0], rest)(fractions)
    return [(p, np.roll(q, 1)) for p, q in zip(positions(fractions), rotations.as_quat())]


def arm_delta_controller(env) -> PDEEPoseController:
    """The env's arm controller, checked to be the delta end-effector pose controller this adapter speaks to."""
    arm = env.agent.controller.controllers.get("arm")
    config = getattr(arm, "config", None)
    if not isinstance(arm, PDEEPoseController) or config.frame != DELTA_FRAME or not config.use_delta or config.use_target:
        raise ValueError(f"the oracle acts in {CONTROL_MODE} ({DELTA_FRAME}, delta from the current pose); the env's arm controller is {arm!r}")
    if not config.normalize_action:
        raise ValueError(f"the oracle acts in {CONTROL_MODE} with normalised actions; the env's arm controller does not normalise them")
    return arm


def speed_limit(controller: PDEEPoseController) -> tuple[float, float]:
    """(metres, radians) per control step the oracle's TCP may move and turn: ``TRANSLATION_SPEED_FRACTION`` of the
    most the controller moves (its smallest position bound) and ``ROTATION_SPEED_FRACTION`` of the most it turns (its
    rotation bound) in a step."""
    low, high = controller.action_space_low.cpu().numpy(), controller.action_space_high.cpu().numpy()
    metres = float(np.minimum(-low[:3], high[:3]).min())
    radians = float(np.abs(np.asarray(controller.config.rot_lower)).min())
    return TRANSLATION_SPEED_FRACTION * metres, ROTATION_SPEED_FRACTION * radians


def delta_action_to(controller: PDEEPoseController, target: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """The normalised ``pd_ee_delta_pose`` arm action that takes the end effector from its pose now to ``target``
    ((position, wxyz quaternion) in the base frame): the inverse of the controller's ``compute_target_pose``
    (translation in the base frame, rotation applied on the left in base-aligned axes as XYZ Euler angles) and of its
    scaling. A move beyond the controller's per-step limits is clipped to them the way the controller clips
    (position per axis, rotation by norm); the next step goes on from wherever this one got to."""
    now = controller.ee_pose_at_base
    position, quaternion = target
    delta_position = position - now.p[0].cpu().numpy()
    rotation_now = quaternion_to_matrix(now.q[0].cpu().double())
    rotation_target = quaternion_to_matrix(torch.as_tensor(quaternion, dtype=torch.float64))
    delta_rotation = matrix_to_euler_angles(rotation_target @ rotation_now.T, "XYZ").numpy()

    low, high = controller.action_space_low.cpu().numpy(), controller.action_space_high.cpu().numpy()
    position_action = inv_scale_action(delta_position, low[:3], high[:3])
    rotation_action = delta_rotation / np.asarray(controller.config.rot_lower, dtype=np.float64)
    return clipped_arm_action(np.concatenate([position_action, rotation_action]))


def clipped_arm_action(arm_action: np.ndarray, position_bound: float = 1.0, rotation_bound: float = 1.0) -> np.ndarray:
    """A normalised arm action (3 translation, 3 rotation) clipped the way the controller clips it: translation per
    axis to ``position_bound``, rotation by norm to ``rotation_bound`` (the turn's direction kept)."""
    position = np.clip(arm_action[:3], -position_bound, position_bound)
    rotation = arm_action[3:]
    norm = np.linalg.norm(rotation)
    if norm > rotation_bound:
        rotation = rotation * (rotation_bound / norm)
    return np.concatenate([position, rotation])

