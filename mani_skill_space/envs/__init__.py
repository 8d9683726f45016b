"""Task environments; importing this module registers every env id with ManiSkill and gymnasium."""

from mani_skill.utils.registration import REGISTERED_ENVS

from mani_skill_space.envs.base import SpaceManipulationEnv
from mani_skill_space.envs.debris_capture import DebrisCaptureEnv
from mani_skill_space.envs.multi_peg_in_hole_assembly import MultiPegInHoleAssemblyEnv
from mani_skill_space.envs.multi_sample_collection import MultiSampleCollectionEnv
from mani_skill_space.envs.peg_in_hole_assembly import PegInHoleAssemblyEnv
from mani_skill_space.envs.sample_collection import SampleCollectionEnv
from mani_skill_space.envs.solar_panel_assembly import SolarPanelAssemblyEnv

TASKS: dict[str, type[SpaceManipulationEnv]] = {
    "SampleCollection-v1": SampleCollectionEnv,
    "PegInHoleAssembly-v1": PegInHoleAssemblyEnv,
    "DebrisCapture-v1": DebrisCaptureEnv,
    "SolarPanelAssembly-v1": SolarPanelAssemblyEnv,
    "MultiSampleCollection-v1": MultiSampleCollectionEnv,
    "MultiPegInHoleAssembly-v1": MultiPegInHoleAssemblyEnv,
}


def task_class(env_id: str) -> type[SpaceManipulationEnv]:
    """The env class registered under ``env_id`` (a ``ValueError`` naming our ids if it is not ours)."""
    if env_id not in TASKS:
        raise ValueError(f"Unknown env id {env_id!r}; valid choices: {', '.join(TASKS)}")
    assert REGISTERED_ENVS[env_id].cls is TASKS[env_id]
    return TASKS[env_id]


__all__ = ["DebrisCaptureEnv", "MultiPegInHoleAssemblyEnv", "MultiSampleCollectionEnv", "PegInHoleAssemblyEnv", "SampleCollectionEnv", "SolarPanelAssemblyEnv", "SpaceManipulationEnv", "TASKS", "task_class"]
