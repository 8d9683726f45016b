"""A closed-loop expert for a peg in the hand, for DAgger: from any state with a peg in the hand, the
``pd_ee_delta_pose`` action that takes it to the socket it should fill, pushes it in and lets go.

The oracle (``oracles.insertion``) is an open-loop plan generator: it cannot be restarted mid-episode with a peg
already in the hand, so it cannot label a learner's own states. Its last part can: the push is a servo that, at
every step, re-measures the peg in the hand and sends the TCP where the peg's end goes next along the socket's axis.
``InsertionPushExpert`` makes the same decision from the scene as it is: line the end up over the socket (rising
to just above the entrance where it is off the axis), push it down the axis, its target a step (``PUSH_STEP``, then ``SEATING_STEP``) ahead
of the end, and, once the peg is inserted, ease off and open the hand. Farther from the socket it
lifts as the oracle does: a peg picked up far from its socket goes straight up to the oracle's carrying height; one
over the socket's axis but high comes down it to ``PRE_INSERT_GAP`` above the entrance. The swing between (a
joint-space motion the oracle plans round the pegs already standing, which straight lines with the controller's
step-wise IK do not reproduce: they stall at joint limits) and everything with no peg in the hand (reaching and
grasping the next peg) have no label: they stay the learner's own.

It speaks to the Solar Panel Assembly env's interface (``pegs``, ``insertion``, ``target_sockets``, the pair
measures of ``evaluate``), single env (``num_envs=1``) on the CPU, as the oracles do.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import sapien
from scipy.spatial.transform import Rotation

from mani_skill_space.oracles.base import GRIPPER_CLOSED, GRIPPER_OPEN, at_height
from mani_skill_space.oracles.end_effector import (
    ROTATION_SPEED_FRACTION,
    TRANSLATION_SPEED_FRACTION,
    arm_delta_controller,
    clipped_arm_action,
    delta_action_to,
)
from mani_skill_space.oracles.insertion import (
    PRE_INSERT_GAP,
    PRESS_DEPTH,
    RELAXED_HEIGHT,
    SEATING_HEIGHT,
    SEATING_STEP,
    _along_axis,
)
from mani_skill_space.oracles.solar_panel import PEG_LIFT_HEIGHT

REGION_RADIUS = 0.03
"""m: the push (lining up and going in) is for a peg end within this distance of its socket's axis..."""
REGION_HEIGHT = 0.06
"""...and at most this far above its entrance; farther, the peg is carried."""
LIFT_RADIUS = 0.1
"""m: a peg whose end is farther than this from its socket's axis is first lifted to ``PEG_LIFT_HEIGHT``."""
LIFT_SLACK = 0.01
CARRY_SPEED_FRACTION = 0.1
"""Share of the controller's per-step translation a peg coming down over its socket moves (1 cm a step)."""
LINED_UP_OFFSET = 0.0007
"""m: an end this close to the axis goes down (the dataset sockets leave 1 mm on each side)."""
LINED_UP_ANGLE = np.radians(1.5)
HOVER_GAP = 0.005
"""m: an end off the axis is lined up at least this far above the entrance (no scraping over the rim)."""
PUSH_STEP = 0.004
"""m per step down the axis above ``SEATING_HEIGHT`` (the Solar oracle's ``insert_step``)."""
BESIDE_OFFSET = 0.003
"""m: an end below the entrance's plane this far off the axis is beside the socket, not in it: it goes back up."""


class InsertionPushExpert:
    """Labels (see the module docstring) for ``env`` (the unwrapped Solar Panel Assembly env, one env)."""

    def __init__(self, env):
        self.env = env
        arm_delta_controller(env)  # checks the control mode

    @property
    def controller(self):
        """The arm's controller now (a reset that rebuilds the scene makes a new one)."""
        return arm_delta_controller(self.env)

    def label(self, info: dict) -> Optional[np.ndarray]:
        """The expert's action in the state ``info`` describes (the env's last ``evaluate``), or None outside its
        region."""
        env = self.env
        held = info["pegs_grasped"][0]
        if not bool(held.any()):
            return None
        peg = int(held.int().argmax())  # the first held
        socket = int(env.target_sockets(info)[0, peg])  # for an inserted peg, the socket it stands in
        end = int(info["pair_peg_end"][0, peg, socket])
        if bool(info["peg_inserted"][0, peg]):  # let go where it stands
            return self._action(peg, end, socket, RELAXED_HEIGHT, GRIPPER_OPEN)
        pair = {key: float(info[f"pair_{key}"][0, peg, socket]) for key in ("inserted_fraction", "lateral_offset", "axis_angle")}
        depth = float(env.insertion.hole_depth[0, socket])
        tip_height = (1.0 - pair["inserted_fraction"]) * depth
        if pair["lateral_offset"] > REGION_RADIUS or tip_height > depth + REGION_HEIGHT:
            return self._carry(peg, end, socket, pair["lateral_offset"], depth)
        return self._action(peg, end, socket, self._goal_height(pair, tip_height, depth), GRIPPER_CLOSED)

    @staticmethod
    def _goal_height(pair: dict, tip_height: float, depth: float) -> float:
        """Where the end goes next, above the socket's bottom along its axis."""
        above_entrance = tip_height > depth
        lined_up = pair["lateral_offset"] <= LINED_UP_OFFSET and pair["axis_angle"] <= LINED_UP_ANGLE
        if above_entrance and not lined_up:
            return max(tip_height, depth + HOVER_GAP)
        if not above_entrance and pair["lateral_offset"] > BESIDE_OFFSET:
            return depth + HOVER_GAP
        # a step ahead of the tip, not of a schedule: the target never runs far below a tip that has stopped
        step = PUSH_STEP if tip_height > SEATING_HEIGHT else SEATING_STEP
        return max(tip_height - step, -PRESS_DEPTH)

    def _carry(self, peg: int, end: int, socket: int, lateral_offset: float, depth: float) -> Optional[np.ndarray]:
        tcp = self.controller.ee_pose.sp
        if lateral_offset > LIFT_RADIUS:
            if tcp.p[2] < PEG_LIFT_HEIGHT - LIFT_SLACK:
                return self._move_to(at_height(tcp, PEG_LIFT_HEIGHT), GRIPPER_CLOSED, TRANSLATION_SPEED_FRACTION)
            return None  # the swing over the socket: a joint-space motion in the oracle's plan, not a straight line
        if lateral_offset > REGION_RADIUS:
            return None
        return self._action(peg, end, socket, depth + PRE_INSERT_GAP, GRIPPER_CLOSED, CARRY_SPEED_FRACTION)

    def _action(self, peg: int, end: int, socket: int, height: float, gripper: float, speed: float = TRANSLATION_SPEED_FRACTION) -> np.ndarray:
        """The action that takes peg ``peg``'s end ``end`` to ``height`` above socket ``socket``'s bottom on its axis."""
        env = self.env
        ends = env.peg_end_frames()[0, peg].cpu().numpy().astype(np.float64)
        bottom = env.insertion.hole_bottom[0, socket].cpu().numpy().astype(np.float64)
        order = int(env.insertion.symmetry_order[0, socket])
        tip_goal = _along_axis(bottom, nearest_twist(np.linalg.inv(bottom) @ ends[end], order), height)
        tcp = self.controller.ee_pose.sp.to_transformation_matrix()
        tip_in_tcp = np.linalg.inv(tcp) @ ends[end]
        return self._move_to(sapien.Pose(tip_goal @ np.linalg.inv(tip_in_tcp)), gripper, speed)

    def _move_to(self, tcp_goal: sapien.Pose, gripper: float, speed: float) -> np.ndarray:
        at_base = self.controller.root_link.pose.sp.inv() * tcp_goal
        arm = slowed(delta_action_to(self.controller, (np.asarray(at_base.p), np.asarray(at_base.q))), speed)
        return np.concatenate([arm, [gripper]]).astype(np.float32)


def nearest_twist(end_in_bottom: np.ndarray, symmetry_order: int) -> float:
    """The twist about the socket's axis (a multiple of the profile's symmetry angle; any, for a round peg) nearest
    the end's, given the end's frame in the socket bottom's: the end turned the shortest way onto the axis first
    (a peg still lying across has no twist of its own about it)."""
    upright = shortest_turn_onto_z(end_in_bottom[:3, 2]) @ end_in_bottom[:3, :3]
    angle = float(np.arctan2(upright[1, 0], upright[0, 0]))
    if symmetry_order == 0:
        return angle
    step = 2.0 * np.pi / symmetry_order
    return float(np.round(angle / step) * step)


def shortest_turn_onto_z(axis: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) by the smallest angle that turns the unit vector ``axis`` onto +z."""
    turn, _ = Rotation.align_vectors([[0.0, 0.0, 1.0]], [axis])  # one pair: the shortest rotation (scipy >= 1.11)
    return turn.as_matrix()


def slowed(arm_action: np.ndarray, position_fraction: float = TRANSLATION_SPEED_FRACTION) -> np.ndarray:
    """A normalised arm action held to a share of the controller's per-step limits, as the oracle's motions are:
    translation per axis to ``position_fraction``, rotation by norm to ``ROTATION_SPEED_FRACTION``."""
    return clipped_arm_action(arm_action, position_fraction, ROTATION_SPEED_FRACTION)
