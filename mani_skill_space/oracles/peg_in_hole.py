"""Oracles for PegInHoleAssembly-v1 and MultiPegInHoleAssembly-v1.

PegInHoleAssembly-v1: the shared peg insertion (``oracles.insertion``) of the env's one peg, with the hole module as
the planner's obstacle (the insertion leaves out the keep-out around the hole's axis, where the fingers go, only
while it lowers the peg in). MultiPegInHoleAssembly-v1: the same insertion four times, one peg after the other."""

from __future__ import annotations

import itertools
from dataclasses import replace
from typing import Iterator, Optional

import numpy as np
import sapien

from mani_skill_space.envs.insertion import INSERTED_FRACTION
from mani_skill_space.oracles.base import FINE_SCREW_STEP, GRIPPER_CLOSED, GRIPPER_OPEN, Oracle, PlanningFailed, collision_vertices, open_finger_corners, surface_points, tcp_pose_with_axes
from mani_skill_space.oracles.insertion import (
    PRESS_DEPTH,
    SETTLE_STEPS,
    STILL_IN_FRACTION,
    InsertionSettings,
    PegInserter,
    PegTarget,
    _frame_holding_tip_over_hole,
    _twists,
    end_nearest,
    inserted_fraction,
    other_pegs,
    stayed_in,
)
from mani_skill_space.oracles.solar_panel import FREE_SPACE_ACCELERATION
from mani_skill_space.oracles.solar_panel import PEG_LIFT_HEIGHT as SOLAR_PEG_LIFT_HEIGHT
from mani_skill_space.oracles.solar_panel import RETREAT_DISTANCES

MODULE_MARGIN = 0.01
"""While taking the peg and carrying it over the hole, the planner keeps the arm this far (m) from the module:
its Panda links are a little slimmer than the simulated ones (the wrist by about a centimetre), and the wrist
reaches over the module's top to take a peg lying in front of it. (Pushing the peg in, the hand comes closer.)"""


PEG_IN_HOLE_INSERTION = InsertionSettings(insert_step=0.004, refine_passes=1)
"""A 10 s episode: the push goes down 4 mm a step after one re-measuring pass over the entrance (with the usual
2.5 mm and two passes, most of the episodes that failed ran out of time)."""


class PegInHoleOracle(Oracle):
    """Oracle for PegInHoleAssembly-v1. Its plan ends with the push: from then on ``Oracle.act`` holds the push's last
    target, so the arm keeps pressing the peg home (waiting for success holding the joints where they are, short of
    that target, the arm eased off and a pressed peg sprang back out)."""

    screw_step = FINE_SCREW_STEP
    quicker_lines_under_tcp_control = True

    def plan(self, env) -> Iterator[np.ndarray]:
        target = PegTarget.of(env, env.peg, 0)
        module = np.eye(4)
        module[:3, 3] = env.hole_module.pose.p[0].cpu().numpy()
        self.make_solver(env, obstacles=surface_points(env.hole_assets[0], module))
        wide_module = surface_points(env.hole_assets[0], module, margin=MODULE_MARGIN, spacing=MODULE_MARGIN)
        yield from PegInserter(self, PEG_IN_HOLE_INSERTION, reach_obstacles=wide_module).insert(target)


NEIGHBOUR_MARGIN = 0.002
"""While a peg is pushed into its hole, the planner keeps the hand this far (m) from the modules beside it: planned
on their bare surfaces, the hand grazed the next module's top, and the push stalled there (orbit, tuning seed 62029:
the third peg 86% of the way in, three pushes running)."""
NEIGHBOUR_SPACING = 0.005
"""m: how far apart those points are."""
MULTI_PEG_STANDING_MARGIN = 0.01
"""The arm keeps this far (m) from the pegs already standing in their holes (``other_pegs``), their edges and corners
included as in Solar Panel Assembly, but half its ``insertion.PEG_MARGIN``: Multi-Peg's pegs stand in modules 0.15 m
wide, not side by side under a panel, and with 2 cm round the three standing the last peg of tuning seed 62016 (Earth
and orbit alike) had no grasp from which the arm lines it up with its hole (with 1 cm it goes in; seeds 62000-62029,
Earth and orbit: 49 -> 51 of 60, none lost)."""

PRESS_HOME_FROM = 0.5
"""A peg let go at least this far in (of its hole's depth: deep enough that the bore holds it upright) but short of
``STILL_IN_FRACTION`` (where the plan would end: it did not stay in) is pressed home with the fingertips
(``MultiPegInHoleOracle._press_home``), and once all four are in, so is any short of the task's ``INSERTED_FRACTION``.
(Pressing every peg short of that at once cost orbit tuning seed 62077 its last peg's time: its first, let go 81% in,
was sliding in by itself.)"""
PRESSED_HOME_FRACTION = 0.97
"""The press ends once the peg is this far in (the socket's latch holds it from ``INSERTED_FRACTION`` on)."""
PRESS_HOME_ABOVE = 0.05
"""How far (m) above the peg's top the fingertips come first, swinging there with the peg as an obstacle."""
PRESS_HOME_GAP = 0.005
"""How far (m) above the peg's top the fingertips come down to before the press."""
PRESS_HOME_STEP = 0.003
"""How far (m) the fingertips go down a control step as they press."""
PRESS_HOME_TURNS = 4
"""Closing directions (about the hole's axis, over half a turn) tried for the pressing hand."""

MULTI_INSERTION_ORDER = (0, 3, 1, 2)
"""Holes in the order they are filled: the outer ones first, so that the arm carrying a peg over an inner module
has the standing pegs beside it, not in the way of its elbow."""
MULTI_PEG_INSERTION = InsertionSettings(
    lift_height=SOLAR_PEG_LIFT_HEIGHT,
    relax_steps=6,
    insert_step=0.004,
    refine_passes=1,
    pre_grasp_acceleration=FREE_SPACE_ACCELERATION,
    replans_when_the_peg_moved=True,
    push_ends_once_seated=True,
    lines_up_again=True,
    regrips_afloat=1,
    shifts_grip_afloat=True,
)
"""Peg-in-Hole's insertion at Solar Panel Assembly's pace (``oracles.solar_panel.PEG_INSERTION``: 4 mm push steps,
one re-measuring pass over the entrance, the empty hand to the pre-grasp pose at twice the accelerations; at
Peg-in-Hole's, 16 of the 28 procedural failures on the tuning seeds ran out of time), the push easing off before the
peg is let go (in orbit a peg let go while pressed in springs back out). The peg is carried over the modules at
``MultiPegInHoleOracle._lift_height``, at most this ``lift_height``: high enough for the dataset's 0.2 m peg
hanging from the hand to clear the pegs already standing (as in Solar Panel Assembly). Where a peg has rolled
between the plan and the hand's arrival over it, its grasp is planned again (``replans_when_the_peg_moved``). A push
ends once the peg is seated (``push_ends_once_seated``): that ends the episodes 27 of their 800 steps sooner on average
(orbit tuning seeds), where the pushes that jam and are tried again take most of what is left."""


LIFT_CLEARANCE = 0.05
"""How far (m) a carried peg's lowest possible point stays above the other pegs' tops (the planner does not see the
peg in the hand)."""


class MultiPegInHoleOracle(Oracle):
    """Oracle for MultiPegInHoleAssembly-v1: Peg-in-Hole's insertion of each peg into its own hole in turn
    (``MULTI_INSERTION_ORDER``, a peg whose insertion cannot start yet left for later:
    ``_first_plannable_insertion``), letting go of it and backing straight up before the next (a peg let go short of
    the way in is pressed home with the fingertips: ``_press_home``), with the modules and
    the other pegs (those standing with a margin) as the planner's obstacles, and, while a peg is pushed in, the
    modules beside its hole's with ``NEIGHBOUR_MARGIN``."""

    screw_step = FINE_SCREW_STEP
    path_check_step = 0.02
    """Standing pegs are thin: a check at 20 points of a long swing can step over one."""
    retreats_straight_up = True
    plans_with_the_fingers_as_they_are = True
    """The empty hand's motion to the next peg starts over the one just inserted: planned with closed fingers, the
    open ones swept through the tops of standing pegs (seeds 62003 and others: the left finger knocked a peg out)."""

    def plan(self, env) -> Iterator[np.ndarray]:
        modules = module_frames(env)
        self._wide_modules = np.concatenate(
            [surface_points(env.hole_assets[i][0], module, margin=MODULE_MARGIN, spacing=MODULE_MARGIN) for i, module in enumerate(modules)]
        )
        self._modules_with_margin = [
            surface_points(env.hole_assets[i][0], module, margin=NEIGHBOUR_MARGIN, spacing=NEIGHBOUR_SPACING) for i, module in enumerate(modules)
        ]
        standing: list[int] = []
        while len(standing) < len(MULTI_INSERTION_ORDER):
            hole, insertion = self._first_plannable_insertion(env, modules, standing)
            yield from insertion
            standing.append(hole)
            yield from self.open_gently(8)
            yield from self.retreat_up(RETREAT_DISTANCES)
            if PRESS_HOME_FROM <= inserted_fraction(env, hole) < STILL_IN_FRACTION:  # short of counting as in
                yield from self._press_home(env, modules, hole, standing)
            if not stayed_in(env, hole):
                raise PlanningFailed(f"peg {hole} did not stay in its hole")
        for hole in MULTI_INSERTION_ORDER:  # in, but short of the depth the task asks for
            if PRESS_HOME_FROM <= inserted_fraction(env, hole) < INSERTED_FRACTION:
                yield from self._press_home(env, modules, hole, standing)
        yield from self.wait_for_success(20)

    def _press_home(self, env, modules: list, hole: int, standing: list) -> Iterator[np.ndarray]:
        """Press peg ``hole``, let go short of the way in, the rest of the way with the closed fingertips on its top,
        pointing down the hole's axis: the hand swings (``joint_move``, at ``FREE_SPACE_ACCELERATION``) to
        ``PRESS_HOME_ABOVE`` over the top, with the peg as an obstacle, comes down to ``PRESS_HOME_GAP`` over it,
        presses it home (``PRESS_HOME_STEP`` a step, until it is ``PRESSED_HOME_FRACTION`` in) and backs straight up,
        opening the fingers. A push whose hand meets the top of the module beside the peg (round a tilted hole that
        top rises toward the peg on one side) stops short whatever the push tries: on orbit tuning seed 62057 every
        push of the second peg stopped 74-90% of the way in, the hand on the module as the planner sees it (no IK
        solution further down), and the peg was let go 74% in. The fingertips on the peg's top stay clear of the
        module. The planner has the modules and the ``standing`` pegs but this one as obstacles. ``PlanningFailed``
        where no such hand pose can be reached."""
        self.make_solver(env, obstacles=self._obstacles(env, modules, hole, tuple(standing)))
        target = PegTarget.of(env, env.pegs[hole], hole)
        axis = target.bottom[:3, 2]  # out of the hole
        ends = target.end_frames()[:, :3, 3]
        inserted_end = ends[int(np.argmin(np.linalg.norm(ends - target.bottom[:3, 3], axis=1)))]
        top = inserted_end + axis * target.height
        reach = float(open_finger_corners(env)[:, 2].max())  # the fingertips' reach past the TCP
        this_peg = other_pegs([env.pegs[hole]], [env.peg_assets[hole][0]], held=-1, standing=[0], margin=MULTI_PEG_STANDING_MARGIN)
        start = self.arm_qpos()
        for pose in self._pressing_poses(top + axis * (reach + PRESS_HOME_ABOVE), axis):
            with self.obstacles_only(lambda points: np.concatenate([points, this_peg])):
                goal = self.free_joint_goal(start, pose)
            if goal is None:
                continue
            self.gripper = GRIPPER_CLOSED
            yield from self.joint_move(goal, "over the peg's top", acceleration=FREE_SPACE_ACCELERATION)
            yield from self.screw_to(sapien.Pose(top + axis * (reach + PRESS_HOME_GAP), pose.q), "onto the peg's top", SETTLE_STEPS)
            low = top + axis * reach - axis * ((1.0 - inserted_fraction(env, hole)) * target.depth + PRESS_DEPTH)
            descent = float((self.tcp_pose().p - low) @ axis)
            steps = int(np.ceil(max(descent, 0.0) / PRESS_HOME_STEP))

            def pressing(step: int) -> sapien.Pose:
                return sapien.Pose(low + axis * max(descent - (step + 1) * PRESS_HOME_STEP, 0.0), pose.q)

            yield from self.servo(pressing, steps + SETTLE_STEPS, "press home", until=lambda step: inserted_fraction(env, hole) >= PRESSED_HOME_FRACTION)
            self.gripper = GRIPPER_OPEN  # opened as the hand backs off, ready for the next peg
            yield from self.retreat_up(RETREAT_DISTANCES)
            return
        raise PlanningFailed(f"no motion to press peg {hole} home")

    def _pressing_poses(self, point: np.ndarray, axis: np.ndarray) -> list[sapien.Pose]:
        """TCP poses at ``point`` pointing down ``axis`` (out of a hole), the closing direction turned about it in
        ``PRESS_HOME_TURNS`` steps, each with its half-turned twin, the one whose fingers close nearer the way the hand's
        close now first."""
        helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        first = np.cross(axis, helper)
        first /= np.linalg.norm(first)
        poses = []
        for angle in np.linspace(0.0, np.pi, PRESS_HOME_TURNS, endpoint=False):
            closing = np.cos(angle) * first + np.sin(angle) * np.cross(axis, first)
            poses.extend(self.closings_nearest_first(tcp_pose_with_axes(point, -axis, closing)))
        return poses

    def _first_plannable_insertion(self, env, modules: list, standing: list) -> tuple[int, Iterator[np.ndarray]]:
        """The next peg to insert and its insertion (actions), its first action already planned: the first peg not yet
        ``standing``, in ``MULTI_INSERTION_ORDER``, whose insertion can start from where the arm and the pegs are now.
        A peg lying beside another can be out of reach until that one is gone: on the tuning seeds, the hand tilted
        over an outer peg came down on the inner peg lying 9 cm beside it (the Panda's hand is 20 cm across). Of the
        last two, the second goes first where the last could not start with the other standing in its hole and the
        other could with it (``_could_start_after``): on orbit tuning seeds 62033 and 62036 the pegs standing in the
        holes either side of the last left it no plan, and the other order inserted all four.
        Where no peg's insertion can start, the first one's failure is raised."""
        waiting = [hole for hole in MULTI_INSERTION_ORDER if hole not in standing]
        if len(waiting) == 2:
            first, last = waiting
            if not self._could_start_after(env, modules, standing, first, last) and self._could_start_after(env, modules, standing, last, first):
                waiting.reverse()
        failures = []
        for hole in waiting:
            insertion = self._insertion(env, modules, hole, standing)
            try:
                first_action = next(insertion)
            except PlanningFailed as failure:  # nothing has moved yet: try the next peg
                failures.append(failure)
                continue
            return hole, itertools.chain([first_action], insertion)
        raise failures[0]

    def _insertion(self, env, modules: list, hole: int, standing: list, seated: Optional[dict] = None) -> Iterator[np.ndarray]:
        """Peg ``hole``'s insertion (actions, planned as they are asked for), with the modules and the other pegs as
        the planner's obstacles (``_obstacles``; ``seated``: pegs at each of these poses instead of where they are), the
        modules with ``MODULE_MARGIN`` for taking and carrying it and those beside its hole's with ``NEIGHBOUR_MARGIN``
        for pushing it in (both made by ``plan``)."""
        self.make_solver(env, obstacles=self._obstacles(env, modules, hole, tuple(standing), seated))
        settings = replace(MULTI_PEG_INSERTION, lift_height=self._lift_height(env, hole, seated))
        beside = np.concatenate([points for i, points in enumerate(self._modules_with_margin) if i != hole])
        return PegInserter(self, settings, reach_obstacles=self._wide_modules, push_obstacles=beside).insert(PegTarget.of(env, env.pegs[hole], hole))

    def _could_start_after(self, env, modules: list, standing: list, first: int, then: int) -> bool:
        """Whether peg ``then``'s insertion could start from where the arm is now if peg ``first`` stood seated in its
        hole too, at whichever twist its insertion takes (``seated_poses``, all of them as obstacles: planned with the
        twist that differed, half a turn, from the one the peg went in with, seed 62033's last peg had a plan it then
        did not have). The arm will have moved by then, but what the standing pegs block is the swing over the hole
        and the push, wherever the arm starts."""
        insertion = self._insertion(env, modules, then, [*standing, first], {first: seated_poses(env, first, self.solver.base_pose.p)})
        try:
            next(insertion)
        except PlanningFailed:
            return False
        return True

    @staticmethod
    def _lift_height(env, hole: int, seated: Optional[dict] = None) -> float:
        """The TCP's height (world z) for carrying peg ``hole`` over the modules: ``LIFT_CLEARANCE`` above the other
        pegs' highest point (those ``seated`` names at the highest of its poses, 4 x 4), plus the held peg's
        bounding-box diagonal (the farthest it can hang below the hand), within Peg-in-Hole's 0.3 m and
        ``MULTI_PEG_INSERTION``'s 0.45 m (enough for the dataset's 0.2 m peg)."""
        seated = seated or {}

        def top(index: int, peg) -> float:
            if index not in seated:
                return float(collision_vertices(peg)[:, 2].max())
            vertices = env.peg_assets[index][0].collision_vertices
            return max(float((vertices @ pose[:3, :3].T + pose[:3, 3])[:, 2].max()) for pose in seated[index])

        tops = max(top(i, peg) for i, peg in enumerate(env.pegs) if i != hole)
        held = env.peg_assets[hole][0].collision_vertices
        hanging = float(np.linalg.norm(held.max(axis=0) - held.min(axis=0)))
        return float(np.clip(tops + hanging + LIFT_CLEARANCE, InsertionSettings.lift_height, MULTI_PEG_INSERTION.lift_height))

    @staticmethod
    def _obstacles(env, modules: list, hole: int, standing: tuple, seated: Optional[dict] = None) -> np.ndarray:
        """The modules and the other pegs where they are now, or at each of the poses ``seated`` gives (``other_pegs``)."""
        points = [surface_points(env.hole_assets[i][0], module) for i, module in enumerate(modules)]
        points.append(other_pegs(env.pegs, [assets[0] for assets in env.peg_assets], hole, standing, seated, margin=MULTI_PEG_STANDING_MARGIN))
        return np.concatenate(points)


def module_frames(env) -> list[np.ndarray]:
    """Each hole module's pose (world, 4 x 4): at its position, unturned."""
    modules = [np.eye(4) for _ in env.pegs]
    for module, position in zip(modules, env.module_positions):
        module[:3, 3] = position
    return modules


def seated_poses(env, hole: int, arm_base: np.ndarray) -> list[np.ndarray]:
    """The poses (world, 4 x 4) peg ``hole`` could have seated at the bottom of its hole, inserted by its end nearest
    the arm's base (``arm_base``, as the insertion does: ``PegInserter._end_toward_arm``), one at each twist its
    profile's symmetry allows."""
    target = PegTarget.of(env, env.pegs[hole], hole)
    tip_in_peg = np.linalg.inv(env.pegs[hole].pose.sp.to_transformation_matrix()) @ target.end_frames()[end_nearest(target, arm_base)]
    return [_frame_holding_tip_over_hole(target, twist, tip_in_peg, 0.0) for twist in _twists(target.symmetry)]
