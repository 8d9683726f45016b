"""Oracle for PegInHoleAssembly-v1: the shared peg insertion (``oracles.insertion``) of the env's one peg, with
the hole module as the planner's obstacle (less the keep-out around the hole's axis, where the fingers go)."""

from __future__ import annotations

from typing import Iterator

import numpy as np

from mani_skill_space.oracles.base import Oracle, surface_points
from mani_skill_space.oracles.insertion import PegInserter, PegTarget, outside_keepout


class PegInHoleOracle(Oracle):
    def plan(self, env) -> Iterator[np.ndarray]:
        target = PegTarget.of(env, env.peg, 0)
        module = np.eye(4)
        module[:3, 3] = env.hole_module.pose.p[0].cpu().numpy()
        self.make_solver(env, obstacles=outside_keepout(surface_points(env.hole_assets[0], module), target))
        yield from PegInserter(self).insert(target)
        yield from self.wait_for_success(20)
