"""Peg insertion as a component the Peg-in-Hole and Solar Panel oracles share.

Before touching the peg it plans the whole insertion: the hand will take the lying peg from above, tilted toward
the peg's tip (and, failing that, rolled about the peg's axis, or with the wrist turned half a turn), which fixes
how it will hold the peg over the hole for each twist the profile's symmetry allows; the first grasp and twist
(the hand pointing down and away from the arm first) for which the arm can reach the pre-grasp and grasp poses,
lift the peg, swing it over the entrance and push it straight to the bottom wins (one whose push keeps
``PUSH_JOINT_MARGIN`` from every joint limit before any that does not). Then: grasp, lift, line the
tip up above the entrance, re-measure the peg in the hand and correct, and servo the tip down the hole's axis,
re-measuring the peg in the hand at every step (the clearance is 1 mm: open-loop paths drift more than that),
its target never more than ``PUSH_LEAD`` ahead of the tip once it is in; a push that jams is backed off and tried
again. A grasp that misses the peg is let go of, the hand backs off (along its approach, else straight up) and the
insertion is planned again with another grasp (``GRASP_ATTEMPTS``). The planner sees the hole's surroundings whole,
except near the hole's axis while the peg goes in (``outside_keepout``), where the fingers holding the peg must pass.

The geometry comes from the env's public ``PegInsertion`` frames (``mani_skill_space.envs.insertion``).
"""

from __future__ import annotations

import itertools
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any, Callable, Generator, Iterable, Iterator, Optional, Sequence

import numpy as np
import sapien
from scipy.spatial.transform import Rotation, Slerp

from mani_skill_space.envs.insertion import SIDE_TOLERANCE
from mani_skill_space.oracles.base import (
    GRIPPER_CLOSED,
    GRIPPER_OPEN,
    GraspMissed,
    Oracle,
    PlanningFailed,
    at_height,
    backed_off,
    box_held_in_hand,
    collision_vertices,
    finger_pad_rectangle,
    inflated_surface_points,
    lowest_point,
    open_finger_corners,
    pad_overlap,
    poses_within,
    raised,
    surface_points,
    turn_between,
    wrist_turned,
)

PRE_GRASP_DISTANCE = 0.08
GRASP_ATTEMPTS = 2
"""Grasps tried on a peg: one whose fingers close on nothing (``GraspMissed``) is let go of, the hand backs off along
its approach (else straight up), and the insertion is planned again from where the peg lies, with no grasp near one
that missed (``MISSED_GRASP_NEIGHBOURHOOD``)."""
BACK_OFF_KEEPOUT = 0.1
"""m: the obstacles this close to the TCP are left out of the planner's while the hand backs off a grasp that missed."""
PEG_MOVED = (0.002, np.radians(2.0))
"""(m, rad): a peg counts as moved since its grasp was planned where that grasp, carried along with the peg, is
now this far from where it was planned (``InsertionSettings.replans_when_the_peg_moved``); a peg dropped from 0.5 mm
onto its resting face, and nothing more, moves less."""
MISSED_GRASP_NEIGHBOURHOOD = (0.01, np.radians(10.0))
"""(m, rad): a grasp this close to one that missed, or to its twin with the wrist turned half a turn (the same grip,
the fingers swapped), in the peg's frame, is not tried again. The angle stays clear of the 15 degrees between
``GRASP_TILTS``: the next tilt at the same grasp point may be tried."""
PAD_REACH = 0.016
"""How far (m) the Panda's finger pads reach along the peg from the grasp point, with the hand tilted by
GRASP_TILT; they must stay above the module while the peg goes in."""
FINGER_MARGIN = 0.006
PAD_HALF_WIDTH = 0.01
"""Half the width of a Panda finger pad (m) beside the peg it grips."""
PAD_EDGE_MARGIN = 0.002
"""m: ``_pads_square_on_sides``: the peg's outermost edge must cross a pad's face at least this far inside its edges."""
FINGER_PRESS_DEPTH = 0.001
"""The hand aims its open fingers at most this far (m) below the surface the peg lies on, so that they press on
it lightly: aimed at a flat peg's axis, a tilted or rolled hand would drive a finger a centimetre into the
ground and be thrown off."""
HEAD_OVERHANG = 0.005
"""The grasp point may be this close to the peg's head: the pads may overhang its end."""
GRASP_TILTS = np.radians([45.0, 30.0, 60.0, 15.0, 0.0])
"""The hand takes the lying peg tilted toward the peg's tip by one of these angles (the first that works and holds
the peg firmly, see ``FIRM_PAD_OVERLAP``). Turned tip-down over the hole, the peg then hangs from a hand pointing
below level, its body rising away from the module's top: a level hand would hit the block beside a short peg. The
steeper hands (15 and 0 degrees) are for flat pegs: a tilted hand's fingertips reach the ground before its pads
come down to a peg a centimetre thick."""
FIRM_PAD_OVERLAP = 0.5
"""A grasp whose finger pads meet the peg over at least this share of their faces (``base.pad_overlap``) holds it
firmly; the others are tried after every firm one, those meeting more of it first (a grasp on the peg's edge or
its end flicks it away as the fingers close, or lets it turn in the hand)."""
GRASP_ROLLS = np.radians([0.0, 25.0, -25.0])
"""...and rolled about the peg's axis by one of these (from straight above first)."""
ROUND_PEG_TWISTS = 8
"""Candidate twists tried for a peg that fits the hole at any twist."""
APPROACH_GAP = 0.1
"""The arm swings the peg over the hole with its tip this far above the entrance, on the hole's axis."""
PRE_INSERT_GAP = 0.03
"""How far above the entrance the tip is lined up before going in."""
LINE_UP_GAPS = (APPROACH_GAP, 0.06, PRE_INSERT_GAP)
"""Where the peg sits in the hand differently than planned and no arm configuration holds it ``APPROACH_GAP`` over
the hole any more, the hand may come lower over it (a lower hand is nearer the arm's base)."""
PRESS_DEPTH = 0.0005
"""The push aims this far beyond the hole's bottom, so the arm keeps pressing the peg home. (Aimed 3 mm beyond it, the
hand drove on after the peg had stopped and turned it between the fingers, past the 5 degrees the task allows, or
the push was retried: on the tuning seeds 7 of 240 pegs were in and came out again.)"""
SEATING_HEIGHT = 0.008
SEATING_STEP = 0.0015
"""The last ``SEATING_HEIGHT`` (m) above the bottom the push goes down at most this far a step: a peg that reaches
the bottom at the full push's pace stops dead while the hand, a couple of steps behind its target, drives on, and
the peg turns between the fingers (6-7 degrees, past the 5 the task allows) or springs back."""
ENOUGH_DEPTH_LEFT = 0.05
"""A push whose tip stops this fraction of the depth above the bottom still inserts the peg (the task asks for
90% of the depth)."""
SETTLE_STEPS = 4
RETRY_BELOW_FRACTION = 0.9
OTHER_BRANCH_JUMP = 1.0
"""rad: a motion of the hand by a few centimetres over the hole that moves a joint this far goes to another branch of
the arm's inverse kinematics (in the traced orbital tuning episodes the way down from ``APPROACH_GAP`` to the entrance
moved each joint by 0.1-0.2 rad, 0.7 where the peg had turned 25 degrees in the hand; seed 62041's fallback joint move
swung the first by 2.2)."""
RELAXED_HEIGHT = 0.0005
"""Where the tip is held, above the bottom, while the push eases off before letting go."""
AXIS_KEEPOUT = 0.04
"""The module's surface within this distance (m) of the peg's side, around the hole's axis, is left out of
the planner's obstacles: the fingers holding the peg come that close to it."""
KEEPOUT_BELOW_ENTRANCE = 0.01
"""...down to this far below the entrance (the fingers hold the peg above it)."""
HELD_PEG_MARGIN = 0.005
"""How far (m) a joint-space swing keeps the held peg's bounding box from the obstacle points, where the settings ask
(``swing_keeps_held_peg_clear``): grown by this, a box at least 1 cm across is wider than the obstacle points' 2 cm
spacing and cannot pass between two of them. (At 1 cm, on Solar Panel Assembly, orbit, procedural, seed 64019, every
grasp whose lift goes straight up lost its swing: the peg passes within 1 cm of the socket base's side.)"""
STILL_IN_FRACTION = 0.8
"""How far in (of its hole's depth) a peg let go must still be to count as having stayed in (``stayed_in``)."""
PUSH_JOINT_MARGIN = 0.15
"""rad: a push planned this close to a joint limit (anywhere along it) is taken only where no other is feasible: the
servo's IK, re-solved from the joints as they are, finds no solution past a limit and the push stalls (traced on
seeds 2000-2049, e.g. orbit 2049: the push stopped 2 mm short of the bottom with nothing touching, the shoulder at
full stretch). The push is measured from where the move over the hole leaves the arm: in ``pd_ee_delta_pose`` not the
configuration moved to (``Oracle.joint_move_end``); there the margin is kept only where the insertion's settings ask
(``PegInserter.push_joint_margin``)."""
SURFACE_CLEARANCE = 0.001
"""m: the fingers closed on a peg pressed home must stay this far above the level surface round the entrance."""
PUSH_LEAD = 0.005
"""m: once the tip is in the hole, the push's target leads it down the axis by at most this much: a target far below
a tip that has stopped presses the peg hard against the wall and turns it in the hand."""
PUSH_EXTRA_STEPS = 8
"""Steps added to every push (the servo runs them all), so that a tip that lags its schedule (``PUSH_LEAD``) still
reaches the bottom."""
SEATED_TIP_HEIGHT = 0.001
"""m: under a TCP controller, where time is what the episodes run out of, a push ends once its schedule has run and
the tip is this close to the bottom (it then eases off to ``RELAXED_HEIGHT`` anyway), not after all the extra steps:
traced on Solar Panel Assembly in ``pd_ee_delta_pose`` (procedural, Moon, seed 6021), every peg counted as inserted
12 steps before its push ended."""
REGRIP_STEPS = 8
"""Control steps over which the open hand turns round a peg let go afloat, back to the grasp it was planned to hold
(``PegInserter._regrip_afloat``)."""
GRIP_SHIFT_FROM = 0.5
"""A peg pushed at least this far in (of its hole's depth: deep enough that the bore holds it upright) and stopped by
the fingers on the surface round the hole may be let go and gripped again farther up (``PegInserter._shift_grip_afloat``)."""
GRIP_SHIFT_MARGIN = 0.003
"""m: the grip shifted up a peg whose fingers met the surface round its hole leaves them this much more than
``SURFACE_CLEARANCE`` above that surface with the peg at the bottom."""
GRIP_SHIFT_OVERLAP = 0.4
"""The grip shifted up the peg keeps at least this share of a finger pad on it (``pad_overlap``): less than a grasp
that lifts a lying peg (``FIRM_PAD_OVERLAP``), as the bore holds the peg upright and the pads only push it in."""
BACK_TO_THE_START_TOLERANCE = 0.1
"""rad: an arm with every joint this close to where it started the episode is not sent back there to plan a grasp
(``PegInserter._goes_back_to_the_start``)."""


@dataclass
class PegTarget:
    """One peg and the hole it goes into, as the oracle sees them (world frame, numpy)."""

    peg: Any
    """The peg's actor (for grasp checks)."""
    end_frames: Callable[[], np.ndarray]
    """The peg's insertable ends now, (2, 4, 4) (the second repeats the first if only one)."""
    end_valid: np.ndarray
    bottom: np.ndarray
    """The hole's bottom frame (z out of the hole)."""
    depth: float
    symmetry: int
    radius: float
    height: float

    @classmethod
    def of(cls, env, peg, index: int) -> "PegTarget":
        """Peg ``index`` of the env's ``insertion`` (its actor ``peg``) and its hole, in the first env."""
        insertion = env.insertion
        return cls(
            peg=peg,
            end_frames=lambda: env.peg_end_frames()[0, index].cpu().numpy().astype(np.float64),
            end_valid=insertion.peg_end_valid[0, index].cpu().numpy(),
            bottom=insertion.hole_bottom[0, index].cpu().numpy().astype(np.float64),
            depth=float(insertion.hole_depth[0, index]),
            symmetry=int(insertion.symmetry_order[0, index]),
            radius=float(insertion.peg_radius[0, index]),
            height=float(insertion.peg_height[0, index]),
        )


@dataclass(frozen=True)
class Swing:
    """How the peg is carried over its hole: a joint-space move to ``arm``, or (``paths`` given, under a TCP controller)
    those joint paths in turn (``PegInserter._straight_swing``), which end at ``arm``."""

    arm: np.ndarray
    paths: tuple = ()


@dataclass(frozen=True)
class InsertionSettings:
    lift_height: float = 0.3
    """Height (m) of the TCP after lifting the peg, before swinging it over the hole."""
    relax_steps: int = 0
    """Steps spent easing off the push at the end of the insertion (for a peg that will be let go)."""
    insert_attempts: int = 3
    """Pushes tried (the first that gets the peg in ends it)."""
    insert_step: float = 0.0025
    """How far (m) the tip goes down the hole's axis per control step while inserting."""
    refine_passes: int = 2
    """How often the tip is re-lined up over the entrance, re-measuring the peg in the hand, before the push."""
    pre_grasp_acceleration: float = 1.0
    """Joint accelerations, as a multiple of the oracle's usual ones, of the empty hand's motion to the pre-grasp
    pose. Where above 1, under a TCP controller the hand catches up with the pre-grasp pose before it goes in to the
    grasp (``Oracle.catch_up``)."""
    carry_acceleration_under_tcp_control: float = 1.0
    """For an oracle acting through a TCP controller (``pd_ee_delta_pose``), joint accelerations, as a multiple of the
    oracle's usual ones, of the held peg's lift and of the straight line that carries it over the hole at the lift
    height (``_straight_swing``): at more than 1 the hand moves ``Oracle.free_space_translation_scale`` times farther a
    step there. The line down to the entrance keeps the usual pace, and so does every motion in joint control."""
    swing_keeps_held_peg_clear: bool = False
    """Whether the joint-space swing over the hole must keep the held peg's box (``PegInserter._held_peg_box``) clear of the
    planner's obstacles (except round the hole's entrance): the planner sees the arm, not the peg hanging from the hand."""
    push_margin_under_tcp_control: bool = False
    """Whether an oracle acting through a TCP controller (``pd_ee_delta_pose``) also prefers pushes that keep
    ``PUSH_JOINT_MARGIN`` from the joint limits (``PegInserter.push_joint_margin``)."""
    push_ends_once_seated: bool = False
    """Whether a push in joint control also ends once its schedule has run and the tip is seated (``SEATED_TIP_HEIGHT``),
    as it does under a TCP controller, rather than after all of ``PUSH_EXTRA_STEPS`` (where the episode's time is
    short for the pushes it asks for: Multi-Peg-in-Hole's four)."""
    replans_when_the_peg_moved: bool = False
    """Whether the grasp is planned again, once, where the peg has moved (``PEG_MOVED``) between the plan and the hand's
    arrival at the pre-grasp pose. A near-round procedural peg (a 32-sided prism) lies at reset on a facet whose edge is
    0.5-2 mm from below its centre of mass, and can roll by up to a facet (11 degrees) in the first steps, while the
    first peg's plan is made at reset (Multi-Peg-in-Hole, Earth, procedural, tuning seeds 62013 and 62026: the first
    peg turned 9.5 and 4.3 degrees, the hand took it 9.8 and 4.7 degrees off the planned grip, and no arm
    configuration lined it up with the hole; planned again, 62013 assembles, and 62026 runs out of time on its last
    peg)."""
    lines_up_again: bool = False
    """Whether the peg is lined up over its hole again (``PegInserter._line_up``: an arm whose push keeps
    ``PUSH_JOINT_MARGIN`` from the joint limits, at any twist the profile allows) where the motion down to the
    entrance would swing the arm onto another branch of its inverse kinematics (``OTHER_BRANCH_JUMP``), or where a
    jammed push has no motion back off above the entrance (the peg has turned in the hand). Traced on Multi-Peg-in-Hole,
    orbit, tuning seed 62041: the screw down to the entrance found no path, the fallback joint move took the arm to a
    configuration with its shoulder 0.07 rad from its limit, and every push stopped there, 47% of the way in; on seeds
    62020 and 62075 a peg held by its rim turned 85 degrees in the hand as the push began, and the back-off had no
    motion."""
    shifts_grip_afloat: bool = False
    """Whether, in zero gravity, a held peg whose push the fingers stop on the surface round the hole (the grasp
    leaves them less than ``SURFACE_CLEARANCE`` above it with the peg at the bottom: a last-resort grasp, or one the
    peg slipped in) at least ``GRIP_SHIFT_FROM`` of the way in is let go there and gripped again farther up the
    peg before the next push (``PegInserter._shift_grip_afloat``)."""
    regrips_afloat: int = 0
    """In zero gravity, how often a held peg whose way over its hole fails with its tip still above the entrance (no
    arm configuration lines it up, or no motion to the pre-insert pose: it has turned in the hand; before a push, or
    backing off after one that jammed) is let go where it is, afloat, and gripped again as the plan meant to hold it
    (``PegInserter._regrip_afloat``)."""


class PegInserter:
    """Grasps a lying peg, lines it up over its hole and pushes it to the bottom, with the motions of ``oracle``
    (whose solver must be ready, with the hole's surroundings as obstacles)."""

    push_obstacles: Optional[np.ndarray] = None

    def __init__(
        self, oracle: Oracle, settings: InsertionSettings = InsertionSettings(), reach_obstacles: Optional[np.ndarray] = None, push_obstacles: Optional[np.ndarray] = None
    ):
        """``reach_obstacles``: more obstacle points (world frame) for the motions that take the peg and carry it
        over the hole (not for the push into it), e.g. the hole's surroundings with a margin. ``push_obstacles``: more
        for the push and the line-up over the entrance, where the keep-out round the hole's axis is left out (e.g.
        the blocks beside the hole's, with a margin)."""
        self.oracle, self.settings = oracle, settings
        self.reach_obstacles = reach_obstacles
        self.push_obstacles = push_obstacles
        self.finger_corners = open_finger_corners(oracle.env)
        self.finger_pad = finger_pad_rectangle(oracle.env)
        self.grasp_on_peg: Optional[sapien.Pose] = None
        """The hand's pose, in the peg's frame, of the grasp that took the peg (``_grasp``)."""
        self.planned_arm: Optional[np.ndarray] = None
        """The arm configuration over the hole that the plan found (its IK seeds the line-up with the peg as it
        really sits in the hand: from elsewhere the solver may find no solution a few millimetres away)."""

    @property
    def push_joint_margin(self) -> float:
        """``PUSH_JOINT_MARGIN``, or none for an oracle whose TCP speed is limited (acting in ``pd_ee_delta_pose``) unless
        its settings ask for it (``push_margin_under_tcp_control``): there a push clear of the limits often comes with a
        grasp that the hand must turn farther to reach, which costs time a single peg's episode does not have
        (procedural pegs, Moon, seeds 6000-6049, in a probe: 56% with the margin, 64% without; the profile peg 92% and
        100% before ``Oracle.joint_move_end``), while a Solar Panel push that stalls leaves a peg unseated and ends the
        plan."""
        if self.oracle.tcp_speed_limit is None or self.settings.push_margin_under_tcp_control:
            return PUSH_JOINT_MARGIN
        return -np.inf

    @property
    def carry_acceleration(self) -> float:
        """``carry_acceleration_under_tcp_control`` for an oracle whose TCP speed is limited, else 1."""
        return self.settings.carry_acceleration_under_tcp_control if self.oracle.tcp_speed_limit is not None else 1.0

    def _near_the_hole(self, target: PegTarget):
        """Plan, inside the block, with the obstacles outside the keep-out round the hole's axis (``outside_keepout``)
        and the ``push_obstacles``."""
        if self.push_obstacles is None:
            return self.oracle.obstacles_only(lambda points: outside_keepout(points, target))
        return self.oracle.obstacles_only(lambda points: np.concatenate([outside_keepout(points, target), self.push_obstacles]))

    def _reaching(self):
        """Plan with the ``reach_obstacles`` too, inside the block."""
        if self.reach_obstacles is None:
            return nullcontext()
        return self.oracle.obstacles_only(lambda points: np.concatenate([points, self.reach_obstacles]))

    def insert(self, target: PegTarget) -> Iterator[np.ndarray]:
        """Grasp the peg, line it up over the hole and push it to the bottom (the solver must be ready); in zero gravity,
        where the way over the hole fails with the peg's tip above the entrance, let go of the peg afloat and grip it
        again as planned, up to ``regrips_afloat`` times."""
        end, twist = yield from self._grasp(target)
        for regrip in itertools.count():
            try:
                twist = yield from self._lift_and_push(target, end, twist)
                break
            except PlanningFailed:
                if regrip >= self.settings.regrips_afloat or not self._can_let_go_afloat(target, end):
                    raise
            yield from self._regrip_afloat(target)
        if self.settings.relax_steps:  # stop pressing, so that the peg rests where it is when let go
            yield from self.oracle.servo(lambda step: self._tcp_for_tip(target, end, _along_axis(target.bottom, twist, RELAXED_HEIGHT)), self.settings.relax_steps, "relax")

    def _afloat(self) -> bool:
        """Whether a peg let go floats where it is (zero gravity)."""
        return not np.any(np.asarray(self.oracle.env.sim_config.scene_config.gravity, dtype=np.float64))

    def _can_let_go_afloat(self, target: PegTarget, end: int) -> bool:
        """Whether the peg, still in the hand, would float where it is let go (zero gravity) and has not gone into its hole
        yet (its tip above the entrance)."""
        if not self._afloat() or not bool(self.oracle.env.is_grasping(target.peg)[0]):
            return False
        return self._inserted_fraction(target, end) < 0.0

    def _regrip_afloat(self, target: PegTarget, grasp_on_peg: Optional[sapien.Pose] = None) -> Iterator[np.ndarray]:
        """Let go of the held peg where it is (gently: it floats on with whatever motion it is let go with), bring the open
        hand round it, over ``REGRIP_STEPS``, to ``grasp_on_peg`` (in the peg's frame, following the peg as it drifts;
        by default the grasp the plan took it with, ``self.grasp_on_peg``), and close the fingers on it again."""
        grasp_on_peg = self.grasp_on_peg if grasp_on_peg is None else grasp_on_peg
        yield from self.oracle.open_gently()
        start = self.oracle.tcp_pose()
        planned = lambda: target.peg.pose.sp * grasp_on_peg  # noqa: E731
        yield from self.oracle.servo(lambda step: _between(start, planned(), min(1.0, (step + 1) / REGRIP_STEPS)), REGRIP_STEPS + SETTLE_STEPS, "regrip")
        yield from self.oracle.set_gripper(GRIPPER_CLOSED)
        yield from self.oracle.wait_for_grasp(target.peg, "the peg")

    def _lift_and_push(self, target: PegTarget, end: int, twist: float) -> Generator[np.ndarray, None, float]:
        """Lift the held peg, line it up over the hole and push it in (again, backing off, where a push jams short of
        ``RETRY_BELOW_FRACTION`` or the fingers stop it on the surface round the hole, up to ``insert_attempts`` pushes;
        in the latter case, afloat, gripped farther up first: ``_shift_grip_afloat``); returns the twist it went in
        with."""
        bottom, depth = target.bottom, target.depth
        with self._reaching():
            yield from self.oracle.screw_to(at_height(self.oracle.tcp_pose(), self.settings.lift_height), "lift", acceleration=self.carry_acceleration)

        for attempt in range(self.settings.insert_attempts):
            line_up = attempt == 0
            if attempt:  # jammed on the rim: back off above the entrance and go again, re-measuring the peg
                if self._fingers_stop_the_push(target, end):
                    yield from self._shift_grip_afloat(target, end)
                with self._near_the_hole(target):
                    back_off = self._tcp_for_tip(target, end, _along_axis(bottom, twist, depth + PRE_INSERT_GAP))
                    if self.settings.lines_up_again and self.oracle.motion_end(self.oracle.arm_qpos(), back_off) is None:
                        line_up = True  # the peg has turned in the hand
                    else:
                        yield from self.oracle.screw_to(back_off, "back off", SETTLE_STEPS)
            twist = yield from self._push_in(target, end, twist, line_up=line_up)
            if self._inserted_fraction(target, end) >= RETRY_BELOW_FRACTION and not self._fingers_stop_the_push(target, end):
                break
        return twist

    def _fingers_stop_the_push(self, target: PegTarget, end: int) -> bool:
        """Where the settings ask (``shifts_grip_afloat``), whether the held peg, floating where it would be let go (zero
        gravity), in its hole at least ``GRIP_SHIFT_FROM`` of the way but not seated, is held so that the fingers come
        down to less than ``SURFACE_CLEARANCE`` above the surface round the hole before it is (``_grip_clearance``),
        and the grip shifted up clear of it (``_shifted_grip``) still holds the peg (``GRIP_SHIFT_OVERLAP``)."""
        if not (self.settings.shifts_grip_afloat and self._afloat() and bool(self.oracle.env.is_grasping(target.peg)[0])):
            return False
        if self._inserted_fraction(target, end) < GRIP_SHIFT_FROM or self._tip_height(target, end) <= SEATED_TIP_HEIGHT:
            return False
        if self._grip_clearance(target, end) >= SURFACE_CLEARANCE:
            return False
        return pad_overlap(self._shifted_grip(target, end), collision_vertices(target.peg), self.finger_pad) >= GRIP_SHIFT_OVERLAP

    def _grip_clearance(self, target: PegTarget, end: int) -> float:
        """How far (m) the fingers holding the peg as the hand does now would stay above the surface round the hole with
        the peg pushed down its axis to the bottom (``_surface_clearance``; negative: below it)."""
        hand = self.oracle.tcp_pose()
        pressed = hand.to_transformation_matrix()
        pressed[:3, 3] -= target.bottom[:3, 2] * self._tip_height(target, end)
        return self._surface_clearance(target, pressed, _grip_half_width(hand, collision_vertices(target.peg)))

    def _shifted_grip(self, target: PegTarget, end: int) -> sapien.Pose:
        """The hand (world) moved up the peg's axis, away from its tip, far enough to leave the fingers
        ``GRIP_SHIFT_MARGIN`` more than ``SURFACE_CLEARANCE`` above the surface round the hole with the peg at the bottom
        (the surface is level, the axis tilted with the hole)."""
        rise = SURFACE_CLEARANCE + GRIP_SHIFT_MARGIN - self._grip_clearance(target, end)
        hand, axis = self.oracle.tcp_pose(), target.end_frames()[end][:3, 2]  # from the tip into the peg
        return sapien.Pose(hand.p + axis * rise / max(float(target.bottom[2, 2]), 0.5), hand.q)

    def _shift_grip_afloat(self, target: PegTarget, end: int) -> Iterator[np.ndarray]:
        """Let go of the peg stopped in its hole by the fingers on the surface round it (``_fingers_stop_the_push``) and
        grip it again farther up its axis (``_shifted_grip``, ``_regrip_afloat``)."""
        yield from self._regrip_afloat(target, _in_frame_of(target.peg, self._shifted_grip(target, end)))

    def _grasp(self, target: PegTarget) -> Generator[np.ndarray, None, tuple[int, float]]:
        """Plan the insertion and take the peg with its grasp, up to ``GRASP_ATTEMPTS`` times (each planned from where
        the peg lies then, away from the grasps that missed); returns the peg's end to insert and the planned twist."""
        missed: list[sapien.Pose] = []
        replanned = False
        while True:
            end = self._end_toward_arm(target)
            grasp, twist = yield from self._plan_grasp_else_from_the_start(target, end, missed)
            grasp_on_peg = _in_frame_of(target.peg, grasp)
            with self._reaching():
                pre_grasp = backed_off(grasp, PRE_GRASP_DISTANCE)
                yield from self.oracle.screw_to(pre_grasp, "pre-grasp", acceleration=self.settings.pre_grasp_acceleration)
                if self.settings.pre_grasp_acceleration > 1.0:  # a brisk motion ends with the hand up to 0.1 m behind
                    yield from self.oracle.catch_up(pre_grasp)
                if self.settings.replans_when_the_peg_moved and not replanned and _peg_moved(target, grasp, grasp_on_peg):
                    replanned = True
                    continue
                yield from self.oracle.screw_to(grasp, "grasp", SETTLE_STEPS)
                yield from self.oracle.set_gripper(GRIPPER_CLOSED)
                try:
                    yield from self.oracle.wait_for_grasp(target.peg, "the peg")
                    self.grasp_on_peg = grasp_on_peg
                    return end, twist
                except GraspMissed:
                    missed.append(grasp_on_peg)
                    if len(missed) >= GRASP_ATTEMPTS:
                        raise
                yield from self.oracle.set_gripper(GRIPPER_OPEN)
                yield from self._back_off_the_peg()

    def _plan_grasp_else_from_the_start(self, target: PegTarget, end: int, missed: Sequence[sapien.Pose]) -> Generator[np.ndarray, None, tuple[sapien.Pose, float]]:
        """``_plan_grasp`` from where the arm is; where that finds no plan under a TCP controller, the arm first goes
        back to where it started the episode (``_goes_back_to_the_start``) and plans from there. The controller's IK
        settles the arm's redundancy its own way, and joint-space moves can leave the elbow and wrist where no grasp
        lines the peg up (traced on Solar Panel Assembly, procedural, Moon, seed 6008 in ``pd_ee_delta_pose``: the
        fourth peg's approach left the arm at (-2.85, -1.53, 1.92, -1.18, 1.39, 1.46, -2.90), from which no plan
        exists, while one does from the start)."""
        try:
            return self._plan_grasp(target, end, missed)
        except PlanningFailed:
            if not self._goes_back_to_the_start(target, end, missed):
                raise
        with self._reaching():
            yield from self.oracle.joint_move(self.oracle.start_qpos, "back to the start")
        return self._plan_grasp(target, end, missed)

    def _goes_back_to_the_start(self, target: PegTarget, end: int, missed: Sequence[sapien.Pose]) -> bool:
        """Whether, under a TCP controller, the arm is to make a joint-space move back to where it started the episode
        (``Oracle.start_qpos``) to plan a grasp: where it is not there yet, the move is free, the controller gets there
        and a plan exists from where it leaves the arm."""
        oracle = self.oracle
        now, start = oracle.arm_qpos(), oracle.start_qpos
        if oracle.arm_follower is None or np.max(np.abs(now - start)) < BACK_TO_THE_START_TOLERANCE:
            return False
        with self._reaching():
            if not oracle.path_is_free(now, start):
                return False
        arrived = oracle.joint_move_end(now, start)
        if arrived is None:
            return False
        try:
            self._plan_grasp(target, end, missed, start=arrived)
        except PlanningFailed:
            return False
        return True

    def _back_off_the_peg(self) -> Iterator[np.ndarray]:
        """From a grasp that missed, the open hand back along its approach, else straight up, planned without the
        obstacles within ``BACK_OFF_KEEPOUT`` of the TCP: the hand came down that way, and the fingers pressed on the
        ground beside the peg may start in collision with its points."""
        hand = self.oracle.tcp_pose()
        away = [move(hand, distance) for distance in (PRE_GRASP_DISTANCE, PRE_GRASP_DISTANCE / 2) for move in (backed_off, raised)]
        with self.oracle.obstacles_only(lambda points: points[np.linalg.norm(points - hand.p, axis=1) > BACK_OFF_KEEPOUT]):
            yield from self.oracle.first_reachable(away, "backing off the peg")

    def _push_in(self, target: PegTarget, end: int, twist: float, line_up: bool) -> Generator[np.ndarray, None, float]:
        """Line the peg up over the hole (if ``line_up``) and push it in; returns the twist it went in with. Where no
        line-up is found from where the arm is, it is sought again once the arm has settled on its last target
        (``Oracle.settle``): the lift ends with the arm trailing it (Solar Panel Assembly, Earth, procedural, tuning
        seed 64047: no line-up for the last peg from where the lift left the arm, one once it had settled)."""
        if line_up:
            twist = yield from self._line_up_and_carry_over(target, end, twist)
        with self._near_the_hole(target):
            lowered = yield from self._lower_in(target, end, twist, keep_branch=self.settings.lines_up_again)
        if not lowered:  # the way down would have left the arm's branch: line up again, then go down as it comes
            twist = yield from self._line_up_and_carry_over(target, end, twist)
            with self._near_the_hole(target):
                yield from self._lower_in(target, end, twist)
        return twist

    def _line_up_and_carry_over(self, target: PegTarget, end: int, twist: float) -> Generator[np.ndarray, None, float]:
        """Line the peg up over the hole (``_line_up``, again once the arm has settled where there is no line-up from
        where it is) and carry it there; returns the twist it goes in with."""
        with self._reaching():
            try:
                swing, twist = self._line_up(target, end, twist)
            except PlanningFailed:
                if not (yield from self.oracle.settle()):
                    raise
                swing, twist = self._line_up(target, end, twist)
            yield from self._carry_over(swing)
        return twist

    def _lower_in(self, target: PegTarget, end: int, twist: float, keep_branch: bool = False) -> Generator[np.ndarray, None, bool]:
        """The tip lined up over the entrance (re-measured ``refine_passes`` more times) and pushed to the bottom;
        returns False, before any motion that would do it, where ``keep_branch`` and a motion down to the entrance
        would swing the arm onto another branch of its inverse kinematics (``_swings_to_another_branch``)."""
        bottom, depth = target.bottom, target.depth
        for _ in range(self.settings.refine_passes + 1):  # re-measure the peg in the hand each time: it may have slipped
            pre_insert = self._tcp_for_tip(target, end, _along_axis(bottom, twist, depth + PRE_INSERT_GAP))
            if keep_branch and self._swings_to_another_branch(pre_insert):
                return False
            yield from self.oracle.line_to(pre_insert, "pre-insert", SETTLE_STEPS)
        heights = _push_heights(depth + PRE_INSERT_GAP, self.settings.insert_step)

        def tip_goal(step: int) -> sapien.Pose:
            height = _led_height(heights[min(step, len(heights) - 1)], self._tip_height(target, end), depth)
            return self._tcp_for_tip(target, end, _along_axis(bottom, twist, height))

        seated = None
        if self.oracle.tcp_speed_limit is not None or self.settings.push_ends_once_seated:
            seated = lambda step: step >= len(heights) and self._tip_height(target, end) <= SEATED_TIP_HEIGHT  # noqa: E731
        yield from self.oracle.servo(tip_goal, len(heights) + SETTLE_STEPS + PUSH_EXTRA_STEPS, "insert", until=seated)
        return True

    def _swings_to_another_branch(self, pose: sapien.Pose) -> bool:
        """Whether the oracle's motion from where the arm is to ``pose`` (a few centimetres of the hand's) would move
        a joint more than ``OTHER_BRANCH_JUMP``."""
        now = self.oracle.arm_qpos()
        arrived = self.oracle.motion_end(now, pose)
        return arrived is not None and float(np.abs(arrived - now).max()) > OTHER_BRANCH_JUMP

    @staticmethod
    def _tip_height(target: PegTarget, end: int) -> float:
        """How far (m) the peg's tip is above the hole's bottom, along its axis."""
        tip = target.end_frames()[end][:3, 3]
        return float((tip - target.bottom[:3, 3]) @ target.bottom[:3, 2])

    @classmethod
    def _inserted_fraction(cls, target: PegTarget, end: int) -> float:
        return 1.0 - cls._tip_height(target, end) / target.depth

    # ------------------------------------------------------------------ planning
    def _plan_grasp(self, target: PegTarget, end: int, missed: Sequence[sapien.Pose] = (), start: Optional[np.ndarray] = None) -> tuple[sapien.Pose, float]:
        """The first grasp (and twist over the hole) for which the whole insertion is feasible from where the arm
        is now: pre-grasp, grasp, lift, the swing over the hole and the straight push to the bottom, and whose push
        keeps ``PUSH_JOINT_MARGIN`` from the joint limits; where no checked grasp's push does, the first feasible
        one. The joint-limit margin thus ranks above the grasps' order (a weaker grasp whose push keeps clear of the
        limits comes before a firm one whose push does not: measured, the stalled pushes cost more than the weaker
        grasps). The unchecked last resorts are only tried where no checked grasp is feasible: the first of them for which
        the insertion is feasible is taken (with the twist whose push keeps the margin, if one does). Under a TCP
        controller (``_takes_the_quickest_plan``) the quickest plan of each of those groups is taken, not the first.
        No grasp near one in ``missed`` (in the peg's frame, ``MISSED_GRASP_NEIGHBOURHOOD``) is tried. ``start``: the
        arm's joints to plan from, where the arm is now by default."""
        tip = target.end_frames()[end]
        outward = target.bottom[:3, 3] - self.oracle.solver.base_pose.p
        outward[2] = 0.0
        outward /= np.linalg.norm(outward)
        start = self.oracle.arm_qpos() if start is None else start
        peg_points = collision_vertices(target.peg)
        grasps = [pose for pose in self._grasp_candidates(target, tip, peg_points) if not _near_any(_in_frame_of(target.peg, pose), missed)]
        # all the checked grasps together (those lifting the peg straight up first, then the others), then each
        # unchecked last resort on its own, ordered only if they are reached (they seldom are)
        checked = [(pose, True) for pose in grasps]
        groups: Iterable[tuple[list, Optional[bool], bool]] = [(checked, True, False), (checked, False, False)]
        if getattr(self.oracle, "moves_in_straight_lines", False):  # the checked grasps with straight swings first
            groups = [(checked, True, True), (checked, False, True)] + groups
        last_resorts = (([(pose, False)], None, False) for pose in self._last_resorts(target, tip, peg_points, grasps))
        for group, straight_lift, straight_swing in itertools.chain(groups, last_resorts):
            if self._takes_the_quickest_plan:
                plan = self._quickest_plan(target, tip, start, outward, peg_points, group, straight_lift, self.push_joint_margin)
            else:
                plans = self._feasible_plans(target, tip, start, outward, peg_points, group, straight_lift, straight_swing)
                if straight_swing:  # first choice only where its push keeps the margin asked for
                    plans = ((plan, margin) for plan, margin in plans if margin >= self.push_joint_margin)
                plan = _clear_else_first(plans, self.push_joint_margin)
            if plan is not None:
                swing, grasp, twist, _ = plan
                self.planned_arm = swing.arm
                return grasp, twist
        raise PlanningFailed("no grasp of the peg lets the arm line it up with the hole and push it in")

    @property
    def _takes_the_quickest_plan(self) -> bool:
        """Under a TCP controller (``pd_ee_delta_pose``) the time the hand takes to turn is what a single peg's episode
        runs out of, and the first feasible plan in the grasps' order can take twice as long as another (procedural
        pegs, Moon, seed 60028: 137 steps of pre-grasp, grasp and swing against 85). There, unless the oracle moves in
        straight lines (Solar Panel Assembly's, whose order is its own), the quickest feasible plan is taken."""
        return self.oracle.tcp_speed_limit is not None and not getattr(self.oracle, "moves_in_straight_lines", False)

    def _quickest_plan(
        self, target: PegTarget, tip: np.ndarray, start: np.ndarray, outward: np.ndarray, peg_points: np.ndarray, group: list, straight_lift: Optional[bool], margin: float
    ) -> Optional[tuple[Swing, sapien.Pose, float, np.ndarray]]:
        """Of the feasible plans of ``group``'s grasps (``_feasible_plans``), the one whose two long motions from
        ``start`` take the fewest control steps at the oracle's pace (the empty hand's to the pre-grasp pose and the
        swing over the hole: grasping and lifting take about as long whatever the plan) among those whose push keeps
        ``margin`` from the joint limits, else among all; among equals, the push farther from the limits, then the
        grasps' order; None if there is none. The grasps are planned in the order of their pre-grasp motions' steps,
        and once a plan keeps the margin, a grasp whose pre-grasp motion alone takes as long is not planned further."""
        usable = [index for index, (grasp, checked) in enumerate(group) if not checked or self._fingers_meet_sides(grasp, peg_points)]
        best = None
        with self._reaching():  # the blocks nested in it keep the same obstacles (``Oracle.obstacles_only``)
            pre_grasp = {index: self.oracle.motion_steps(start, backed_off(group[index][0], PRE_GRASP_DISTANCE), self.settings.pre_grasp_acceleration) for index in usable}
            for steps, index in sorted((steps, index) for index, steps in pre_grasp.items() if steps is not None):
                if best is not None and not best[0][0] and steps >= best[0][1]:
                    break
                for rank, (plan, plan_margin) in enumerate(self._feasible_plans(target, tip, start, outward, peg_points, [group[index]], straight_lift)):
                    key = (plan_margin < margin, steps + self._swing_steps(plan), -plan_margin, index, rank)
                    if best is None or key < best[0]:
                        best = (key, plan)
        return None if best is None else best[1]

    def _swing_steps(self, plan: tuple[Swing, sapien.Pose, float, np.ndarray]) -> int:
        """Control steps of a plan's (swing, grasp, twist, arm after the lift) swing over the hole."""
        swing, _, _, lifted = plan
        return self._steps_of_swing(lifted, swing)

    def _steps_of_swing(self, start: np.ndarray, swing: Swing) -> int:
        """Control steps of ``swing`` from the arm's joints ``start``."""
        if swing.paths:
            return sum(len(path) for path in swing.paths)
        return self.oracle.joint_move_steps(start, swing.arm)

    def _feasible_plans(
        self,
        target: PegTarget,
        tip: np.ndarray,
        start: np.ndarray,
        outward: np.ndarray,
        peg_points: np.ndarray,
        candidates: list,
        straight_lift: Optional[bool] = None,
        straight_swing: bool = False,
    ) -> Iterator[tuple[tuple[Swing, sapien.Pose, float, np.ndarray], float]]:
        """For each of ``candidates`` (grasp, whether its fingers are checked) in turn and each twist over the hole
        (the hand pointing down and away from the arm first), the plans (swing over the hole, grasp, twist, the arm
        after the lift) for which the whole insertion is feasible from ``start`` (only those whose lift is, or with
        False is not, a straight screw motion up, as ``straight_lift`` says), each with its push's joint-limit margin."""
        depth = target.depth
        for grasp, checked in candidates:
            if checked and not self._fingers_meet_sides(grasp, peg_points):
                continue
            with self._reaching():
                lifted = self._grasp_and_lift_end(start, grasp, straight_lift)
            if lifted is None:
                continue
            tip_in_hand = _tip_in_hand(grasp, tip)
            held_box = self._held_peg_box(target, peg_points, grasp.to_transformation_matrix())
            grip_half_width = _grip_half_width(grasp, peg_points)
            hand_over_hole = lambda twist: _frame_holding_tip_over_hole(target, twist, tip_in_hand, depth)  # noqa: E731
            # the hand pointing down and away from the arm first
            score = lambda twist: 2.0 * hand_over_hole(twist)[2, 2] - hand_over_hole(twist)[:3, 2] @ outward  # noqa: E731
            holding = np.full_like(self.oracle.finger_qpos(), grip_half_width)  # each finger closed on the peg
            for twist in sorted(_twists(target.symmetry), key=score):
                pressed = _frame_holding_tip_over_hole(target, twist, tip_in_hand, 0.0)
                if checked and not self._fingers_clear_surface(target, pressed, grip_half_width):
                    continue
                with self._reaching(), self.oracle.fingers_planned_at(holding):
                    found = self._swing_over(target, twist, tip_in_hand, start=lifted, straight_only=straight_swing, held_box=held_box)
                if found is not None:
                    yield (found[0], grasp, float(twist), lifted), found[1]

    def _fingers_meet_sides(self, grasp: sapien.Pose, peg_points: np.ndarray) -> bool:
        """Whether each finger, closing from ``grasp`` on the lying peg (its collision vertices ``peg_points``),
        reaches down to where the peg sticks out farthest on its side: a hand rolled over a flat peg holds one
        finger above it, and the grasp misses."""
        across = _across_fingers(grasp, peg_points)
        corners = self.finger_corners @ grasp.to_transformation_matrix()[:3, :3].T + grasp.p
        corner_side = _across_fingers(grasp, corners)
        for side in (1.0, -1.0):
            outermost = side * across >= (side * across).max() - SIDE_TOLERANCE
            contact_height = peg_points[outermost, 2].min()
            if corners[side * corner_side > 0, 2].min() > contact_height + SIDE_TOLERANCE:
                return False
        return True

    def _pads_square_on_sides(self, grasp: sapien.Pose, peg_points: np.ndarray) -> bool:
        """Whether, on each side, the lying peg's outermost edge across the fingers (its collision vertices
        ``peg_points`` within ``SIDE_TOLERANCE`` of the farthest) crosses the finger pad's face at least
        ``PAD_EDGE_MARGIN`` inside its edges, so that the pads press flat on the peg. Where the pad's edge meets
        a slanted face of the peg instead, the contact pushes along that face's normal and the squeeze wedges the
        peg out of the grip as it is lifted."""
        local = (peg_points - grasp.p) @ grasp.to_transformation_matrix()[:3, :3]
        low, high = self.finger_pad[0] + PAD_EDGE_MARGIN, self.finger_pad[1] - PAD_EDGE_MARGIN
        fractions = np.linspace(0.0, 1.0, 11)[:, None]
        for side in (1.0, -1.0):
            across = side * local[:, 1]
            edge = local[across >= across.max() - SIDE_TOLERANCE][:, [0, 2]]
            samples = np.concatenate([a + fractions * (b - a) for a in edge for b in edge])
            if not np.any(np.all((samples >= low) & (samples <= high), axis=1)):
                return False
        return True

    def _grasp_and_lift_end(self, start: np.ndarray, grasp: sapien.Pose, straight_lift: Optional[bool] = None) -> Optional[np.ndarray]:
        """Arm joints after the pre-grasp, grasp and lift motions from ``start``, or None if one would fail, if the hand
        cannot come in to the grasp in a straight line (``Oracle.straight_motion_end``), or if the lift is not
        (``straight_lift`` True) or is (False) a straight screw motion up. The peg is not among the planner's obstacles,
        and a joint-space move in to the grasp swings the open fingers off the line of approach and into it (traced on
        Multi-Peg, orbit, seed 62021: 38 mm off the line, the finger knocked the last peg afloat). Where there is no
        straight lift, the lift is a joint-space move to another configuration of the arm, which can whirl the peg out
        of the fingers; a grasp whose lift is straight was already planned with the straight ones, so False leaves it
        out."""
        arm = self.oracle.motion_end(start, backed_off(grasp, PRE_GRASP_DISTANCE), self.settings.pre_grasp_acceleration)
        arm = None if arm is None else self.oracle.straight_motion_end(arm, grasp)
        if arm is None:
            return None
        lift = at_height(grasp, self.settings.lift_height)
        straight = self.oracle.screw_end(arm, lift)
        if straight_lift is None or straight_lift == (straight is not None):
            return straight if straight is not None else self.oracle.free_joint_goal(arm, lift)
        return None

    def _line_up(self, target: PegTarget, end: int, twist: float) -> tuple[np.ndarray, float]:
        """An arm configuration over the hole, and its twist, given how the hand really holds the peg now (not
        quite as planned: the fingers close on it where they meet it): the planned twist if its push still keeps
        ``PUSH_JOINT_MARGIN`` from the joint limits, else the nearest other one the profile's symmetry allows that
        does, then the same with the last resorts (a push that may stop just short of the bottom, the hand lower
        over the hole; the margin is that of the push planned); where none keeps the margin, the first feasible
        one in that order. (The fingers' clearance round the hole is not checked again here.)"""
        tip_in_hand = np.linalg.inv(self.oracle.tcp_pose().to_transformation_matrix()) @ target.end_frames()[end]
        held_box = self._held_peg_box(target, collision_vertices(target.peg), self.oracle.tcp_pose().to_transformation_matrix())
        twists = sorted(_twists(target.symmetry), key=lambda other: abs(np.angle(np.exp(1j * (other - twist)))))

        def line_ups() -> Iterator[tuple[tuple[np.ndarray, float], float]]:
            # a push that stops just short of the bottom still inserts the peg, and the hand may come lower over the
            # hole, nearer the arm's reach: the last resorts
            for approach_gap in LINE_UP_GAPS:
                for push_to in (-PRESS_DEPTH, ENOUGH_DEPTH_LEFT * target.depth):
                    for candidate in twists:
                        found = self._swing_over(target, candidate, tip_in_hand, start=self.oracle.arm_qpos(), push_to=push_to, approach_gap=approach_gap, held_box=held_box)
                        if found is not None:
                            yield (found[0], float(candidate)), found[1]

        line_up = _clear_else_first(line_ups(), self.push_joint_margin)
        if line_up is not None:
            return line_up
        raise PlanningFailed("the peg moved in the hand: no arm configuration lines it up with the hole any more")

    def _carry_over(self, swing: Swing) -> Iterator[np.ndarray]:
        if not swing.paths:
            yield from self.oracle.joint_move(swing.arm, "over the hole")
        for path in swing.paths:
            yield from self.oracle.follow(path, "over the hole")

    def _swing_over(
        self,
        target: PegTarget,
        twist,
        tip_in_hand,
        start: Optional[np.ndarray] = None,
        push_to: float = -PRESS_DEPTH,
        approach_gap: float = APPROACH_GAP,
        straight_only: bool = False,
        held_box: Optional[tuple[np.ndarray, np.ndarray]] = None,
    ) -> Optional[tuple[Swing, float]]:
        """How to carry the peg (``tip_in_hand``) from ``start`` to ``approach_gap`` over the hole at ``twist``, with the
        margin of the push from there (as ``_insertion_arm``): where the oracle moves in straight lines, the straight swing
        (``_straight_swing``) where its push keeps the margin the insertion asks for (``push_joint_margin``), else the
        joint-space move to an arm configuration over the hole (``_insertion_arm``), else whichever push keeps farther
        from the limits; None if there is neither (``straight_only``: the straight swing or None). Where the quickest
        plan is taken (``_takes_the_quickest_plan``), the quicker of the joint-space move and the straight swing among
        those whose push keeps the margin, else whichever push keeps farther from the limits: the controller takes the
        hand along the whole whirl of a joint-space move (procedural peg, Moon, seed 6046 in ``pd_ee_delta_pose``: 100
        steps and 3.8 rad of turning to carry the peg 0.19 m and turn it 2.65 rad, and the push ran out of time; the
        straight swing took 40). ``held_box``: the held peg's box (``PegInserter._held_peg_box``), which the joint-space move keeps clear of
        the obstacles where the settings ask (``swing_keeps_held_peg_clear``)."""
        quickest = start is not None and self._takes_the_quickest_plan
        straight = None
        if start is not None and (getattr(self.oracle, "moves_in_straight_lines", False) or quickest):
            straight = self._straight_swing(target, twist, tip_in_hand, start, push_to, approach_gap)
        if straight_only or (not quickest and straight is not None and straight[1] >= self.push_joint_margin):
            return straight
        found = self._insertion_arm(target, twist, tip_in_hand, start, push_to, approach_gap, held_box)
        joint = None if found is None else (Swing(found[0]), found[1])
        if quickest:
            keeping = [swing for swing in (joint, straight) if swing is not None and swing[1] >= self.push_joint_margin]
            if keeping:
                return min(keeping, key=lambda swing: self._steps_of_swing(start, swing[0]))
        feasible = [swing for swing in (joint, straight) if swing is not None]
        return max(feasible, key=lambda swing: swing[1]) if feasible else None

    def _straight_swing(self, target: PegTarget, twist, tip_in_hand, start: np.ndarray, push_to: float, approach_gap: float) -> Optional[tuple[Swing, float]]:
        """The hand in a straight line from ``start`` to its pose over the hole raised to the lift height (the peg turned
        above the module, not through it), then straight down to it (``Oracle.hand_line``), with the margin of the push
        from there; None where either line collides or stalls, or no push follows."""
        over = self._hand_over_hole(target, twist, tip_in_hand, target.depth + approach_gap)
        high = at_height(over, max(self.settings.lift_height, float(over.p[2])))
        paths, arm = [], start
        for pose, acceleration in ((high, self.carry_acceleration), (over, 1.0)):
            path = self.oracle.hand_line(arm, pose, acceleration)
            if path is None:
                return None
            paths.append(path)
            arm = path[-1]
        with self._near_the_hole(target):
            margin = self.oracle.screw_limit_margin(arm, self._hand_over_hole(target, twist, tip_in_hand, push_to))
        return None if margin is None else (Swing(arm, tuple(paths)), margin)

    @staticmethod
    def _hand_over_hole(target: PegTarget, twist, tip_in_hand, height: float) -> sapien.Pose:
        """The hand pose holding the tip (``tip_in_hand``) ``height`` above the hole's bottom on its axis, at ``twist``."""
        return sapien.Pose(_frame_holding_tip_over_hole(target, twist, tip_in_hand, height))

    def _insertion_arm(
        self,
        target: PegTarget,
        twist,
        tip_in_hand,
        start: Optional[np.ndarray] = None,
        push_to: float = -PRESS_DEPTH,
        approach_gap: float = APPROACH_GAP,
        held_box: Optional[tuple[np.ndarray, np.ndarray]] = None,
    ) -> Optional[tuple[np.ndarray, float]]:
        """An arm configuration holding the tip ``approach_gap`` over the hole on its axis (with ``tip_in_hand``) from which a
        straight push reaches ``push_to`` above the bottom (just past it by default), and (given ``start``) a straight joint move reaches it,
        with the push's least joint-limit margin: the first whose push keeps ``PUSH_JOINT_MARGIN`` from the limits, else the
        one whose push keeps farthest from them; None if there is none. Given ``start``, the push is planned from where the
        move really leaves the arm (``Oracle.joint_move_end``: under a TCP controller, not the configuration moved to)."""
        pressed = self._hand_over_hole(target, twist, tip_in_hand, push_to)
        over = self._hand_over_hole(target, twist, tip_in_hand, target.depth + approach_gap)
        solutions = self.oracle.ik_solutions(over)
        if self.planned_arm is not None:
            solutions = self.oracle.ik_solutions(over, near=self.planned_arm)[:1] + solutions
        arms = [arm for arm in solutions if start is None or self.oracle.path_is_free(start, arm)]
        best = None
        with self._near_the_hole(target):
            for arm in arms:
                reached = arm if start is None else self.oracle.joint_move_end(start, arm)
                if reached is None:
                    continue
                margin = self.oracle.screw_limit_margin(reached, pressed)
                if margin is None:
                    continue
                keeps_margin = margin >= self.push_joint_margin
                if not keeps_margin and best is not None and margin <= best[1]:
                    continue
                if start is not None and not self._keeps_held_peg_clear(start, arm, held_box):  # checked last: the dearest
                    continue
                if keeps_margin:
                    return arm, margin
                best = (arm, margin)
        return best

    def _held_peg_box(self, target: PegTarget, peg_points: np.ndarray, hand: np.ndarray) -> Optional[tuple[np.ndarray, np.ndarray]]:
        """The peg's bounding box in its own frame (of its collision vertices where it is now, ``peg_points``, world),
        grown by ``HELD_PEG_MARGIN``, as the hand at ``hand`` (world, 4 x 4) holds the peg where it is now: its pose in the
        TCP frame and its half extents (``Oracle.path_keeps_held_box_clear``); None where the settings do not ask for it
        (``swing_keeps_held_peg_clear``)."""
        if not self.settings.swing_keeps_held_peg_clear:
            return None
        peg = target.peg.pose.sp.to_transformation_matrix()
        in_peg = (peg_points - peg[:3, 3]) @ peg[:3, :3]
        return box_held_in_hand(in_peg, peg, hand, HELD_PEG_MARGIN)

    def _keeps_held_peg_clear(self, start: np.ndarray, arm: np.ndarray, held_box: Optional[tuple[np.ndarray, np.ndarray]]) -> bool:
        """Whether the straight joint move from ``start`` to ``arm`` keeps ``held_box`` clear of the obstacles in use
        (``_insertion_arm`` leaves out the hole's keep-out, where the swing brings the peg's tip); True where there is no
        box to keep clear."""
        if held_box is None:
            return True
        return self.oracle.path_keeps_held_box_clear(start, arm, *held_box)

    def _grasp_candidates(self, target: PegTarget, tip: np.ndarray, peg_points: np.ndarray) -> list[sapien.Pose]:
        """Hand poses taking the lying peg (its collision vertices ``peg_points``), most natural first: every grasp
        tilt, then the hand rolled about the peg's axis, each also turned a half turn about its approach (the same
        grip, another wrist angle); then all of these again farther from the tip, where the hole is tilted (see
        ``_surface_rise``). Those whose pads meet the peg firmly (``FIRM_PAD_OVERLAP``) come first, in that order
        (those whose pads also press squarely on its sides, ``_pads_square_on_sides``, before the rest), then the
        others, those meeting more of the peg first; a grasp whose pads miss the peg altogether is never
        tried. ``_plan_grasp`` tries them with their fingers checked (``_fingers_meet_sides``,
        ``_fingers_clear_surface``), then, as the last resort, all of them again unchecked in the order
        ``_last_resorts`` gives (the checks are conservative: a grasp that fails them may still get the peg 90% of
        the way in)."""
        rise = self._surface_rise(target)
        reaches = (0.0, rise) if rise > FINGER_MARGIN else (0.0,)
        candidates = []
        for extra_reach in reaches:
            for roll in GRASP_ROLLS:
                for tilt in GRASP_TILTS:
                    grasp = self._grasp_pose(target, tip, tilt, roll, extra_reach)
                    for pose in self._wrist_turns(grasp):
                        candidates.append((pose, pad_overlap(pose, peg_points, self.finger_pad)))
        firm = [pose for pose, overlap in candidates if overlap >= FIRM_PAD_OVERLAP]
        firm.sort(key=lambda pose: not self._pads_square_on_sides(pose, peg_points))  # stable: square first
        weak = [pose for pose, overlap in sorted(candidates, key=lambda c: -c[1]) if 0.0 < overlap < FIRM_PAD_OVERLAP]
        return firm + weak

    def _last_resorts(self, target: PegTarget, tip: np.ndarray, peg_points: np.ndarray, grasps: list) -> list:
        """``grasps`` again, unchecked: those whose fingers meet the peg's sides first, then those whose fingers come
        nearest to clearing the surface round the hole with the peg at the bottom (at their best twist) first. Taken in
        the grasps' own order, the first last resort's finger met the module round a tilted hole and stopped the peg 78%
        of the way in, on every push (Multi-Peg, orbit, seed 62005: the fingers 5 mm below that surface as planned)."""

        def clearance(grasp: sapien.Pose) -> float:
            tip_in_hand, grip_half_width = _tip_in_hand(grasp, tip), _grip_half_width(grasp, peg_points)
            return max(self._surface_clearance(target, _frame_holding_tip_over_hole(target, twist, tip_in_hand, 0.0), grip_half_width) for twist in _twists(target.symmetry))

        return sorted(grasps, key=lambda grasp: (not self._fingers_meet_sides(grasp, peg_points), -clearance(grasp)))

    def _wrist_turns(self, grasp: sapien.Pose) -> tuple[sapien.Pose, sapien.Pose]:
        """``grasp`` and the same grip with the hand turned half a turn about its approach; where the oracle moves in
        straight lines under a TCP controller, the one the hand turns less to reach from where it is first: turning is
        what bounds that controller (a pre-grasp turning 3 rad takes 66 steps)."""
        turns = (grasp, wrist_turned(grasp))
        if not getattr(self.oracle, "moves_in_straight_lines", False):
            return turns
        hand = self.oracle.tcp_pose()
        return tuple(sorted(turns, key=lambda pose: turn_between(hand.q, pose.q)))

    @staticmethod
    def _surface_rise(target: PegTarget) -> float:
        """How far (m, along the hole's axis) the level surface round a tilted hole rises above its entrance beside
        the peg, where the fingers holding it come down: the surface is not square to the axis."""
        tilt = np.arccos(np.clip(target.bottom[2, 2], -1.0, 1.0))
        return (target.radius + PAD_HALF_WIDTH) * np.tan(min(tilt, np.radians(60.0)))

    def _fingers_clear_surface(self, target: PegTarget, hand_pressed: np.ndarray, grip_half_width: float) -> bool:
        """Whether the fingers, closed on the peg (``grip_half_width`` either side of the TCP, across the closing
        axis) by a hand at ``hand_pressed`` (the peg at the hole's bottom), stay above the level surface round the
        hole's entrance."""
        return bool(self._surface_clearance(target, hand_pressed, grip_half_width) >= SURFACE_CLEARANCE)

    def _surface_clearance(self, target: PegTarget, hand_pressed: np.ndarray, grip_half_width: float) -> float:
        """How far (m) the fingers closed on the peg by a hand at ``hand_pressed`` stay above the level surface round
        the hole's entrance (negative: below it)."""
        corners = self.finger_corners.copy()
        inner = np.abs(corners[:, 1]).min()  # the open fingers' inner faces, across the closing (y) axis
        corners[:, 1] -= np.sign(corners[:, 1]) * max(0.0, inner - grip_half_width)
        lowest = (corners @ hand_pressed[:3, :3].T + hand_pressed[:3, 3])[:, 2].min()
        bottom = target.bottom
        return float(lowest - (bottom[2, 3] + target.depth * bottom[2, 2]))

    def _grasp_pose(self, target: PegTarget, tip: np.ndarray, tilt: float, roll: float = 0.0, extra_reach: float = 0.0) -> sapien.Pose:
        """Hand pose taking the lying peg from above, tilted by ``tilt`` toward its tip and rolled by ``roll``
        about its axis, with the finger pads far enough from the tip to stay out of the hole (and ``extra_reach``
        farther)."""
        axis = tip[:3, 2]
        height, depth = target.height, target.depth
        reach = min(max(depth + PAD_REACH + FINGER_MARGIN + extra_reach, height / 2), height - HEAD_OVERHANG)
        closing = np.cross(axis, [0.0, 0.0, 1.0])
        closing /= np.linalg.norm(closing)
        upward = np.cross(closing, axis)
        upward *= np.sign(upward[2])
        upward, closing = np.cos(roll) * upward + np.sin(roll) * closing, np.cos(roll) * closing - np.sin(roll) * upward
        approach = -np.sin(tilt) * axis - np.cos(tilt) * upward
        grasp = self.oracle.env.agent.build_grasp_pose(approach, closing, tip[:3, 3] + reach * axis)
        # a flat peg's axis lies lower than the open fingers can reach (the finger pads still span its widest part)
        fingers_low = (self.finger_corners @ grasp.to_transformation_matrix()[:3, :3].T)[:, 2].min()
        rise = max(0.0, lowest_point(target.peg) - FINGER_PRESS_DEPTH - (grasp.p[2] + fingers_low))
        return sapien.Pose(grasp.p + [0.0, 0.0, rise], grasp.q)

    def _end_toward_arm(self, target: PegTarget) -> int:
        """Of the insertable ends, the one nearest the arm: the hand, tilted toward the tip, then comes from the
        far side of the peg and keeps clear of the rover."""
        return end_nearest(target, self.oracle.solver.base_pose.p)

    # ------------------------------------------------------------------ measuring
    def _tcp_for_tip(self, target: PegTarget, end: int, tip_goal: np.ndarray) -> sapien.Pose:
        """The TCP pose that puts the peg's end at ``tip_goal``, given how the hand holds the peg right now."""
        tip_in_tcp = np.linalg.inv(self.oracle.tcp_pose().to_transformation_matrix()) @ target.end_frames()[end]
        return sapien.Pose(tip_goal @ np.linalg.inv(tip_in_tcp))


PEG_MARGIN = 0.02
"""The arm keeps about this far (m) from the pegs already standing in their holes, edges and corners included
(``inflated_surface_points``), in Solar Panel Assembly (Multi-Peg-in-Hole keeps its own
``peg_in_hole.MULTI_PEG_STANDING_MARGIN``). (Not around the pegs still lying on the deck: the hand must reach between them.)"""
STANDING_PEG_SPACING = 0.005
"""The standing pegs' obstacle points this far apart: at the usual 2 cm spacing an open finger can pass between two
points on a standing peg's top and knock it out of its socket."""


def inserted_fraction(env, peg: int) -> float:
    """How far in (of its hole's depth) peg ``peg`` is in hole ``peg`` (of the env's ``insertion``)."""
    return float(env.evaluate()["pair_inserted_fraction"][0, peg, peg])


def stayed_in(env, peg: int) -> bool:
    """Whether peg ``peg``, let go, is still in hole ``peg`` (of the env's ``insertion``): at least ``STILL_IN_FRACTION``
    of the way in, with its end within the peg's radius of the hole's axis. A peg may lean in the clearance; one
    dropped beside the hole lies deeper than the bottom's plane, far off the axis."""
    info = env.evaluate()
    fraction = float(info["pair_inserted_fraction"][0, peg, peg])
    off_axis = float(info["pair_lateral_offset"][0, peg, peg])
    return fraction >= STILL_IN_FRACTION and off_axis <= float(env.insertion.peg_radius[0, peg])


def end_nearest(target: PegTarget, point: np.ndarray) -> int:
    """Of the peg's insertable ends, the one nearest ``point`` seen from above."""
    ends = target.end_frames()
    distance = [np.linalg.norm(ends[i][:2, 3] - point[:2]) if target.end_valid[i] else np.inf for i in range(len(ends))]
    return int(np.argmin(distance))


def other_pegs(pegs: list, peg_assets: list, held: int, standing, poses: Optional[dict] = None, margin: float = PEG_MARGIN) -> np.ndarray:
    """Obstacle points of every peg but ``held``, where it is now (or at each of the poses, 4 x 4, that ``poses`` lists
    for its index): those ``standing`` in their holes with ``margin`` (an open finger must not knock one out),
    those still lying without (the hand reaches between them)."""
    poses = poses or {}
    points = []
    for i, peg in enumerate(pegs):
        if i != held:
            in_peg = inflated_surface_points(peg_assets[i], margin=margin, spacing=STANDING_PEG_SPACING) if i in standing else surface_points(peg_assets[i])
            points += [in_peg @ pose[:3, :3].T + pose[:3, 3] for pose in poses.get(i, [peg.pose.sp.to_transformation_matrix()])]
    return np.concatenate(points)


def outside_keepout(points: np.ndarray, target: PegTarget) -> np.ndarray:
    """Obstacle points except around the hole's axis near its entrance, where the peg and the fingers holding
    it go in (deeper down, e.g. a post's sides, they stay: the hand must not run into them on its way)."""
    return outside_hole_keepout(points, target.bottom, target.depth, target.radius)


def outside_hole_keepout(points: np.ndarray, bottom: np.ndarray, depth: float, peg_radius: float) -> np.ndarray:
    """``outside_keepout`` for a hole with its ``bottom`` frame (world, 4 x 4), ``depth`` and its peg's radius."""
    offset = points - bottom[:3, 3]
    along = offset @ bottom[:3, 2]
    lateral = np.linalg.norm(offset - along[:, None] * bottom[None, :3, 2], axis=1)
    near_entrance = along > depth - KEEPOUT_BELOW_ENTRANCE
    return points[(lateral > peg_radius + AXIS_KEEPOUT) | ~near_entrance]


def _peg_moved(target: PegTarget, grasp: sapien.Pose, grasp_on_peg: sapien.Pose) -> bool:
    """Whether the peg has moved by ``PEG_MOVED`` since ``grasp`` (world) was planned on it (``grasp_on_peg``: the
    grasp in the peg's frame then): the grasp carried with the peg to where it lies now is that far from it."""
    moved = target.peg.pose.sp * grasp_on_peg
    return not poses_within((grasp.p, grasp.q), (moved.p, moved.q), PEG_MOVED)


def _between(start: sapien.Pose, end: sapien.Pose, fraction: float) -> sapien.Pose:
    """The pose ``fraction`` of the way from ``start`` to ``end``: its position on the line between them, its
    orientation on the shortest arc between theirs."""
    turns = Rotation.from_quat(np.array([start.q, end.q])[:, [1, 2, 3, 0]])
    turn = Slerp([0.0, 1.0], turns)([fraction]).as_quat()[0]
    return sapien.Pose(start.p + fraction * (end.p - start.p), turn[[3, 0, 1, 2]])


def _in_frame_of(actor, pose: sapien.Pose) -> sapien.Pose:
    """``pose`` (world frame) in ``actor``'s frame now."""
    return actor.pose.sp.inv() * pose


def _near_any(pose: sapien.Pose, others: Sequence[sapien.Pose], neighbourhood: tuple[float, float] = MISSED_GRASP_NEIGHBOURHOOD) -> bool:
    """Whether the grip of the hand at ``pose`` is within ``neighbourhood`` (m, rad) of that of any of ``others`` (in
    the same frame): a hand turned half a turn about its approach grips the same way (its fingers swapped), so each of
    ``others`` counts with its wrist-turned twin."""
    twins = [twin for other in others for twin in (other, wrist_turned(other))]
    return any(poses_within((pose.p, pose.q), (twin.p, twin.q), neighbourhood) for twin in twins)


def _tip_in_hand(grasp: sapien.Pose, tip: np.ndarray) -> np.ndarray:
    """The peg's end frame ``tip`` in the frame of a hand at ``grasp``."""
    return np.linalg.inv(grasp.to_transformation_matrix()) @ tip


def _grip_half_width(grasp: sapien.Pose, peg_points: np.ndarray) -> float:
    """How far (m) either finger closed from ``grasp`` stops from the TCP: the peg's (``peg_points``) farthest point
    across the fingers."""
    return float(np.abs(_across_fingers(grasp, peg_points)).max())


def _frame_holding_tip_over_hole(target: PegTarget, twist: float, tip_in_frame: np.ndarray, height: float) -> np.ndarray:
    """The pose (world, 4x4) of a frame (the hand's, or the peg's own) that holds the peg's tip (``tip_in_frame``)
    ``height`` above the hole's bottom on its axis, at ``twist``: at 0, the peg pressed to the bottom."""
    return _along_axis(target.bottom, twist, height) @ np.linalg.inv(tip_in_frame)


def _across_fingers(hand: sapien.Pose, points: np.ndarray) -> np.ndarray:
    """Where ``points`` (k, 3, world) lie along the hand's closing (y) axis, from its TCP."""
    return (points - hand.p) @ hand.to_transformation_matrix()[:3, 1]


def _push_heights(start: float, step: float) -> np.ndarray:
    """The tip's height above the hole's bottom at each step of a push from ``start``: down ``step`` a step to
    ``SEATING_HEIGHT``, then ``SEATING_STEP`` a step to ``PRESS_DEPTH`` below the bottom."""
    fast = np.arange(start - step, SEATING_HEIGHT, -step)
    slow = np.arange(min(SEATING_HEIGHT, start), -PRESS_DEPTH, -SEATING_STEP)
    return np.concatenate([fast, slow, [-PRESS_DEPTH]])


def _clear_else_first(plans: Iterable[tuple[Any, float]], margin: float) -> Optional[Any]:
    """Of ``plans`` (each with its push's joint-limit margin), the first whose push keeps ``margin`` from the limits,
    else the first; None if there is none. Stops drawing plans at the first that keeps the margin."""
    first = None
    for plan, plan_margin in plans:
        if plan_margin >= margin:
            return plan
        if first is None:
            first = plan
    return first


def _led_height(scheduled: float, tip_height: float, depth: float) -> float:
    """The push's target height for the tip (above the hole's bottom): the schedule's, but once the tip is in the
    hole (below ``depth``) no more than ``PUSH_LEAD`` below where the tip is."""
    return max(scheduled, tip_height - PUSH_LEAD) if tip_height < depth else scheduled


def _twists(order: int) -> np.ndarray:
    count = ROUND_PEG_TWISTS if order == 0 else order
    return np.arange(count) * 2 * np.pi / count


def _along_axis(bottom: np.ndarray, twist: float, height: float) -> np.ndarray:
    """The hole's bottom frame turned by ``twist`` about its axis and raised ``height`` along it."""
    c, s = np.cos(twist), np.sin(twist)
    turn = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, height], [0, 0, 0, 1]])
    return bottom @ turn
