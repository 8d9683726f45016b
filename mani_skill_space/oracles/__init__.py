"""Motion-planning oracles, one per task: privileged step-by-step policies (see ``base.Oracle``)."""

from __future__ import annotations

from mani_skill_space.oracles.base import Oracle, PlanningFailed
from mani_skill_space.oracles.debris_capture import DebrisCaptureOracle
from mani_skill_space.oracles.peg_in_hole import PegInHoleOracle
from mani_skill_space.oracles.sample_collection import SampleCollectionOracle
from mani_skill_space.oracles.solar_panel import SolarPanelOracle

ORACLES: dict[str, type[Oracle]] = {
    "SampleCollection-v1": SampleCollectionOracle,
    "PegInHoleAssembly-v1": PegInHoleOracle,
    "DebrisCapture-v1": DebrisCaptureOracle,
    "SolarPanelAssembly-v1": SolarPanelOracle,
}


def oracle_for(env_id: str) -> Oracle:
    if env_id not in ORACLES:
        raise ValueError(f"No oracle for {env_id!r}; oracles exist for: {', '.join(ORACLES)}")
    return ORACLES[env_id]()


__all__ = ["ORACLES", "Oracle", "PlanningFailed", "oracle_for"]
