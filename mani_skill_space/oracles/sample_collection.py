"""Oracle for SampleCollection-v1: grasp the sample from above, lift, swing over the bin, lower it in, release."""

from __future__ import annotations

from typing import Iterator

import numpy as np
import sapien

from mani_skill_space.oracles.base import GRIPPER_CLOSED, GRIPPER_OPEN, Oracle, PlanningFailed, top_down_grasp_pose

PRE_GRASP_HEIGHT = 0.08
SETTLE_STEPS = 4
"""Control steps holding the grasp pose before closing, so the fingers reach it despite the PD tracking lag."""
LIFT_HEIGHT = 0.3
"""Height of the TCP above the ground while carrying the sample."""
CARRY_HEIGHT = 0.5
"""TCP height over the bin before lowering the sample in (the rim is at 0.33 m)."""
RELEASE_HEIGHT_ABOVE_FLOOR = 0.06
SETTLE_IN_BIN_STEPS = 25
"""At most this many steps of waiting, after the retreat, for the released sample to come to rest."""
DROP_OFFSET = (0.0, 0.06)
"""Where over the bin floor the sample is released, relative to its centre (y toward the sample's side)."""


class SampleCollectionOracle(Oracle):
    def plan(self, env) -> Iterator[np.ndarray]:
        self.make_solver(env)
        grasp = top_down_grasp_pose(env, env.sample)
        grasp = sapien.Pose([grasp.p[0], grasp.p[1], max(grasp.p[2], 0.012)], grasp.q)
        yield from self.screw_to(_raised(grasp, PRE_GRASP_HEIGHT), "pre-grasp")
        yield from self.screw_to(grasp, "grasp", settle_steps=SETTLE_STEPS)
        yield from self.set_gripper(GRIPPER_CLOSED)
        yield from self.screw_to(_at_height(grasp, LIFT_HEIGHT), "lift")

        over_bin, release, goal = self._bin_approach(env, side=1.0 if grasp.p[1] >= 0 else -1.0)
        yield from self.joint_move(goal, "over-bin")
        yield from self.screw_to(release, "release")
        yield from self.set_gripper(GRIPPER_OPEN)
        yield from self.screw_to(over_bin, "retreat")
        yield from self.wait_for_success(SETTLE_IN_BIN_STEPS)

    def _bin_approach(self, env, side: float) -> tuple[sapien.Pose, sapien.Pose, np.ndarray]:
        """A pose over the bin, the release pose below it and an arm configuration reaching the first, such that
        the arm can swing there and then lower straight down. The gripper may point its fingers along x or y,
        both ways (it is symmetric): whichever the arm reaches first."""
        floor = env.mount.frames["bin"][:3, 3]
        drop_xy = floor[:2] + np.array([DROP_OFFSET[0], side * DROP_OFFSET[1]])
        for yaw in (np.pi / 2, -np.pi / 2, 0.0, np.pi):
            over_bin = sapien.Pose([*drop_xy, CARRY_HEIGHT], _top_down(yaw))
            release = sapien.Pose([*drop_xy, floor[2] + RELEASE_HEIGHT_ABOVE_FLOOR], over_bin.q)
            for goal in self.ik_solutions(over_bin):
                if self.path_is_free(self.arm_qpos(), goal) and self.screw_is_feasible(goal, release):
                    return over_bin, release, goal
        raise PlanningFailed("cannot reach over the bin and lower the sample into it")


def _raised(pose: sapien.Pose, height: float) -> sapien.Pose:
    return sapien.Pose(pose.p + np.array([0.0, 0.0, height]), pose.q)


def _at_height(pose: sapien.Pose, height: float) -> sapien.Pose:
    return sapien.Pose([pose.p[0], pose.p[1], height], pose.q)


def _top_down(yaw: float) -> np.ndarray:
    """Top-down TCP orientation (approach -z) with its closing axis turned by ``yaw`` about z."""
    down = sapien.Pose(q=[0.0, 1.0, 0.0, 0.0])  # TCP z axis pointing down
    turn = sapien.Pose(q=[np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
    return (turn * down).q
