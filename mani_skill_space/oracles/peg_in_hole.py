"""Oracle for PegInHoleAssembly-v1: the shared peg insertion (``oracles.insertion``) of the env's one peg, with
the hole module as the planner's obstacle (the insertion leaves out the keep-out around the hole's axis, where the
fingers go, only while it lowers the peg in)."""

from __future__ import annotations

from typing import Iterator

import numpy as np

from mani_skill_space.oracles.base import Oracle, surface_points
from mani_skill_space.oracles.insertion import PegInserter, PegTarget

MODULE_MARGIN = 0.01
"""While taking the peg and carrying it over the hole, the planner keeps the arm this far (m) from the module:
its Panda links are a little slimmer than the simulated ones (the wrist by about a centimetre), and the wrist
reaches over the module's top to take a peg lying in front of it. (Pushing the peg in, the hand comes closer.)"""


class PegInHoleOracle(Oracle):
    def plan(self, env) -> Iterator[np.ndarray]:
        target = PegTarget.of(env, env.peg, 0)
        module = np.eye(4)
        module[:3, 3] = env.hole_module.pose.p[0].cpu().numpy()
        self.make_solver(env, obstacles=surface_points(env.hole_assets[0], module))
        wide_module = surface_points(env.hole_assets[0], module, margin=MODULE_MARGIN, spacing=MODULE_MARGIN)
        yield from PegInserter(self, reach_obstacles=wide_module).insert(target)
        yield from self.wait_for_success(20)
