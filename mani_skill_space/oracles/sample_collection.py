"""Oracles for SampleCollection-v1 (grasp the sample from above, lift, swing over the bin, lower it in, release)
and MultiSampleCollection-v1 (the same for each of its samples in turn)."""

from __future__ import annotations

from typing import Iterator, Optional

import numpy as np
import sapien

from mani_skill_space.oracles.base import GRIPPER_CLOSED, GRIPPER_OPEN, Oracle, PlanningFailed, at_height, raised, top_down_grasp_pose

PRE_GRASP_HEIGHT = 0.06
SETTLE_STEPS = 3
"""Control steps holding the grasp (release) pose before closing (opening) the hand, so that the fingers reach it
despite the PD tracking lag and the sample is let go at rest (else it may roll in the bin)."""
LIFT_HEIGHT = 0.3
"""Height of the TCP above the ground when the arm starts to swing the sample over to the bin."""
SWING_FLOOR = 0.25
"""The TCP stays above this height during the swing: the held sample (which the planner does not know of)
clears the rover's deck (0.2 m) and chassis."""
CARRY_HEIGHT = 0.45
"""TCP height over the bin before lowering the sample in (the rim is at 0.33 m)."""
RELEASE_HEIGHT_ABOVE_FLOOR = 0.06
SETTLE_IN_BIN_STEPS = 25
"""At most this many steps of waiting, after the retreat, for the released sample to come to rest."""
JOINT_LIMIT_MARGIN = 0.5
"""Over the bin, the arm prefers configurations at least this far (rad) from its joint limits."""
DROP_OFFSET = (0.0, 0.06)
AXIS_TOLERANCE = np.radians(30.0)
"""Where over the bin floor the sample is released, relative to its centre (y toward the sample's side)."""


class SampleCollectionOracle(Oracle):
    tcp_pace = (0.045, 0.035)
    """The fastest pace at which the demonstrations convert to ``pd_ee_delta_pose`` step for step (its PD lag
    clips faster rotations): converted, they first succeed after about 125 of the episode's 150 steps."""

    def plan(self, env) -> Iterator[np.ndarray]:
        self.make_solver(env)
        yield from self.collect(env, env.sample, drop_offset=None)
        yield from self.wait_for_success(SETTLE_IN_BIN_STEPS)

    def collect(
        self, env, sample, drop_offset, release_height: float = RELEASE_HEIGHT_ABOVE_FLOOR, axis_yaw: Optional[float] = None, swing_to_grasp: bool = False
    ) -> Iterator[np.ndarray]:
        """Grasp ``sample`` from above, lift it, swing it over the bin and let go of it ``release_height`` above the
        bin's floor at ``drop_offset`` (x, y) from the floor's centre (None: ``DROP_OFFSET`` on the sample's side),
        then retreat straight up. ``axis_yaw``: the direction the hand's x axis should preferably take over the bin
        (``_bin_approach``);
        ``swing_to_grasp``: reach the pre-grasp pose by a joint-space swing (from over the bin), not a screw."""
        grasp = top_down_grasp_pose(env, sample)
        pre_grasp = raised(grasp, PRE_GRASP_HEIGHT)
        if swing_to_grasp:
            goal = self.free_joint_goal(self.arm_qpos(), pre_grasp)
            if goal is None:
                raise PlanningFailed("no swing to the pre-grasp pose")
            yield from self.joint_move(goal, "pre-grasp")
        else:
            yield from self.screw_to(pre_grasp, "pre-grasp")
        yield from self.screw_to(grasp, "grasp", settle_steps=SETTLE_STEPS)
        yield from self.set_gripper(GRIPPER_CLOSED)
        yield from self.screw_to(at_height(grasp, LIFT_HEIGHT), "lift")

        if drop_offset is None:
            drop_offset = (DROP_OFFSET[0], DROP_OFFSET[1] if grasp.p[1] >= 0 else -DROP_OFFSET[1])
        over_bin, release, goal = self._bin_approach(env, drop_offset, release_height, axis_yaw)
        yield from self.joint_move(goal, "over-bin")
        yield from self.screw_to(release, "release", settle_steps=SETTLE_STEPS)
        yield from self.set_gripper(GRIPPER_OPEN)
        yield from self.screw_to(over_bin, "retreat")

    def _bin_approach(self, env, drop_offset: tuple[float, float], release_height: float, axis_yaw: Optional[float] = None) -> tuple[sapien.Pose, sapien.Pose, np.ndarray]:
        """A pose over the bin, the release pose below it and an arm configuration reaching the first, such that
        the arm can swing there and then lower straight down. The bin takes the sample at any heading, so of the
        four headings (the one carried, a quarter and a half turn; and ``axis_yaw`` both ways round, where given:
        headings more than ``AXIS_TOLERANCE`` from it come after the others) and their IK solutions, the swing that keeps
        the TCP above ``SWING_FLOOR`` in the fewest steps at the TCP pace wins (a needless turn of the hand costs
        tens of steps, which demonstrations converted to ``pd_ee_delta_pose`` cannot spend in a 150-step
        episode). Configurations near a joint limit come last: the Cartesian controller reaches the pose on a
        joint path of its own and would be stopped by the limit."""
        floor = env.mount.frames["bin"][:3, 3]
        drop_xy = floor[:2] + np.asarray(drop_offset)
        start = self.arm_qpos()
        candidates = []
        yaws = _tcp_heading(env) + np.array([0.0, np.pi / 2, -np.pi / 2, np.pi])
        if axis_yaw is not None:
            yaws = np.concatenate([yaws, [axis_yaw, axis_yaw + np.pi]])
        for yaw in yaws:
            over_bin = sapien.Pose([*drop_xy, CARRY_HEIGHT], _top_down(yaw))
            release = sapien.Pose([*drop_xy, floor[2] + release_height], over_bin.q)
            for goal in self.ik_solutions(over_bin):
                positions, rotations = self.tcp_path(start, goal)
                if positions[:, 2].min() >= SWING_FLOOR:
                    misaligned = axis_yaw is not None and abs(np.sin(yaw - axis_yaw)) > np.sin(AXIS_TOLERANCE)
                    candidates.append((misaligned, self.steps_along(positions, rotations), over_bin, release, goal))
        near_limit = lambda goal: self.joint_limit_margin(goal) < JOINT_LIMIT_MARGIN  # noqa: E731
        for _, _, over_bin, release, goal in sorted(candidates, key=lambda candidate: (candidate[0], near_limit(candidate[4]), candidate[1])):
            if self.path_is_free(start, goal) and self.screw_is_feasible(goal, release):
                return over_bin, release, goal
        raise PlanningFailed("cannot reach over the bin and lower the sample into it")


def _tcp_heading(env) -> float:
    """The yaw of a top-down TCP, as ``_top_down`` parameterises it (the TCP x axis is (cos yaw, sin yaw, 0))."""
    x_axis = env.agent.tcp.pose.to_transformation_matrix()[0, :3, 0].cpu().numpy()
    return float(np.arctan2(x_axis[1], x_axis[0]))


def _top_down(yaw: float) -> np.ndarray:
    """Top-down TCP orientation (approach -z) with its closing axis turned by ``yaw`` about z."""
    down = sapien.Pose(q=[0.0, 1.0, 0.0, 0.0])  # TCP z axis pointing down
    turn = sapien.Pose(q=[np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
    return (turn * down).q


MULTI_DROPS = (((0.0, 0.08), RELEASE_HEIGHT_ABOVE_FLOOR), ((0.0, -0.08), RELEASE_HEIGHT_ABOVE_FLOOR), ((0.0, 0.0), RELEASE_HEIGHT_ABOVE_FLOOR + 0.05))
"""Where over the bin each sample of MultiSampleCollection is let go, in the order they are collected: two on
either side of the floor, the third between them and higher (it may land on the others)."""


class MultiSampleCollectionOracle(SampleCollectionOracle):
    tcp_pace = None
    """Three samples in 7.5 s each leave no time for the single-sample oracle's pace: the arm moves at the planner's
    joint limits (or, acting in ``pd_ee_delta_pose``, at the end-effector adapter's speed limit)."""

    def steps_along(self, positions: np.ndarray, rotations: list) -> float:
        """Candidate swings are still ranked by their length at the single-sample oracle's pace."""
        return float(self._paces(positions, rotations, pace=SampleCollectionOracle.tcp_pace).sum())

    def plan(self, env) -> Iterator[np.ndarray]:
        self.make_solver(env)
        for sample, (offset, height) in zip(self._collection_order(env), MULTI_DROPS):
            # the hand's x axis (a tube's axis) along the bin's x side, preferably: side by side, three tubes fit
            yield from self.collect(env, sample, offset, height, axis_yaw=0.0, swing_to_grasp=True)
        yield from self.wait_for_success(SETTLE_IN_BIN_STEPS)

    @staticmethod
    def _collection_order(env) -> list:
        """Outer lanes first (left, right), then the middle: each drop goes on the side of the bin nearer its lane."""
        left, middle, right = sorted(env.samples, key=lambda sample: -float(sample.pose.p[0, 1]))
        return [left, right, middle]
