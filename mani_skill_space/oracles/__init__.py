"""Motion-planning oracles, one per task: privileged step-by-step policies (see ``base.Oracle``)."""

from __future__ import annotations

from typing import Union

from mani_skill_space.oracles.base import Oracle, PlanningFailed
from mani_skill_space.oracles.debris_capture import DebrisCaptureOracle
from mani_skill_space.oracles.end_effector import CONTROL_MODE, EndEffectorDeltaPose
from mani_skill_space.oracles.peg_in_hole import MultiPegInHoleOracle, PegInHoleOracle
from mani_skill_space.oracles.sample_collection import MultiSampleCollectionOracle, SampleCollectionOracle
from mani_skill_space.oracles.solar_panel import SolarPanelOracle

ORACLES: dict[str, type[Oracle]] = {
    "SampleCollection-v1": SampleCollectionOracle,
    "PegInHoleAssembly-v1": PegInHoleOracle,
    "DebrisCapture-v1": DebrisCaptureOracle,
    "SolarPanelAssembly-v1": SolarPanelOracle,
    "MultiSampleCollection-v1": MultiSampleCollectionOracle,
    "MultiPegInHoleAssembly-v1": MultiPegInHoleOracle,
}


ORACLE_CONTROL_MODES = ("pd_joint_pos", CONTROL_MODE)
"""The control modes an oracle acts in: its own joint targets, or the end-effector deltas that reach them."""


def oracle_for(env_id: str, control_mode: str = "pd_joint_pos") -> Union[Oracle, EndEffectorDeltaPose]:
    """The oracle of ``env_id``, acting in ``control_mode``."""
    if env_id not in ORACLES:
        raise ValueError(f"No oracle for {env_id!r}; oracles exist for: {', '.join(ORACLES)}")
    if control_mode not in ORACLE_CONTROL_MODES:
        raise ValueError(f"the oracles act in no control mode {control_mode!r}; valid choices: {', '.join(ORACLE_CONTROL_MODES)}")
    oracle = ORACLES[env_id]()
    return oracle if control_mode == "pd_joint_pos" else EndEffectorDeltaPose(oracle)


__all__ = ["ORACLES", "ORACLE_CONTROL_MODES", "EndEffectorDeltaPose", "Oracle", "PlanningFailed", "oracle_for"]
