"""Oracle for SampleCollection-v1: grasp the sample from above, lift, swing over the bin, lower it in, release."""

from __future__ import annotations

from typing import Iterator

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
"""Where over the bin floor the sample is released, relative to its centre (y toward the sample's side)."""


class SampleCollectionOracle(Oracle):
    tcp_pace = (0.045, 0.035)
    """The fastest pace at which the demonstrations convert to ``pd_ee_delta_pose`` step for step (its PD lag
    clips faster rotations): converted, they first succeed after about 125 of the episode's 150 steps."""

    def plan(self, env) -> Iterator[np.ndarray]:
        self.make_solver(env)
        grasp = top_down_grasp_pose(env, env.sample)
        grasp = sapien.Pose([grasp.p[0], grasp.p[1], max(grasp.p[2], 0.012)], grasp.q)
        yield from self.screw_to(raised(grasp, PRE_GRASP_HEIGHT), "pre-grasp")
        yield from self.screw_to(grasp, "grasp", settle_steps=SETTLE_STEPS)
        yield from self.set_gripper(GRIPPER_CLOSED)
        yield from self.screw_to(at_height(grasp, LIFT_HEIGHT), "lift")

        over_bin, release, goal = self._bin_approach(env, side=1.0 if grasp.p[1] >= 0 else -1.0)
        yield from self.joint_move(goal, "over-bin")
        yield from self.screw_to(release, "release", settle_steps=SETTLE_STEPS)
        yield from self.set_gripper(GRIPPER_OPEN)
        yield from self.screw_to(over_bin, "retreat")
        yield from self.wait_for_success(SETTLE_IN_BIN_STEPS)

    def _bin_approach(self, env, side: float) -> tuple[sapien.Pose, sapien.Pose, np.ndarray]:
        """A pose over the bin, the release pose below it and an arm configuration reaching the first, such that
        the arm can swing there and then lower straight down. The bin takes the sample at any heading, so of the
        four headings (the one carried, a quarter and a half turn) and their IK solutions, the swing that keeps
        the TCP above ``SWING_FLOOR`` in the fewest steps at the TCP pace wins (a needless turn of the hand costs
        tens of steps, which demonstrations converted to ``pd_ee_delta_pose`` cannot spend in a 150-step
        episode). Configurations near a joint limit come last: the Cartesian controller reaches the pose on a
        joint path of its own and would be stopped by the limit."""
        floor = env.mount.frames["bin"][:3, 3]
        drop_xy = floor[:2] + np.array([DROP_OFFSET[0], side * DROP_OFFSET[1]])
        start = self.arm_qpos()
        candidates = []
        for yaw in _tcp_heading(env) + np.array([0.0, np.pi / 2, -np.pi / 2, np.pi]):
            over_bin = sapien.Pose([*drop_xy, CARRY_HEIGHT], _top_down(yaw))
            release = sapien.Pose([*drop_xy, floor[2] + RELEASE_HEIGHT_ABOVE_FLOOR], over_bin.q)
            for goal in self.ik_solutions(over_bin):
                positions, rotations = self.tcp_path(start, goal)
                if positions[:, 2].min() >= SWING_FLOOR:
                    candidates.append((self.steps_along(positions, rotations), over_bin, release, goal))
        near_limit = lambda goal: self.joint_limit_margin(goal) < JOINT_LIMIT_MARGIN  # noqa: E731
        for _, over_bin, release, goal in sorted(candidates, key=lambda candidate: (near_limit(candidate[3]), candidate[0])):
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
