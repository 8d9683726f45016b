"""The free-floating servicer's agent: ManiSkill's arm agent, loaded from ``procgen.servicer``'s description (the arm
on a bus) with its root link free."""

from __future__ import annotations

import hashlib
import os
import tempfile
from functools import lru_cache
from pathlib import Path

from mani_skill.agents.base_agent import BaseAgent

from mani_skill_space.procgen.cache import default_cache_dir
from mani_skill_space.procgen.servicer import servicer_urdf


@lru_cache(maxsize=None)
def servicer_agent_class(arm_class: type[BaseAgent], mass: float) -> type[BaseAgent]:
    """``arm_class`` (e.g. ManiSkill's Panda) standing on a free-floating bus of ``mass`` kg: the same uid,
    controllers, keyframes and cameras, its description written once to the asset cache (``arm_urdf_path``: the arm's
    own, for motion planners that plan the arm from the bus's pose)."""
    arm_path = Path(arm_class.urdf_path)
    text = servicer_urdf(arm_path.read_text(), arm_path.parent, mass)
    name = f"{arm_class.uid}_{hashlib.sha256(text.encode()).hexdigest()[:16]}.urdf"
    try:
        path = _written(default_cache_dir() / "servicer" / name, text)
    except OSError:  # an unwritable cache: the system's temporary folder
        path = _written(Path(tempfile.gettempdir()) / "mani_skill_space_servicer" / name, text)
    return type(f"{arm_class.__name__}Servicer", (arm_class,), {"urdf_path": str(path), "arm_urdf_path": str(arm_path), "fix_root_link": False})


def _written(path: Path, text: str) -> Path:
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        temporary = path.with_name(f"{path.name}.{os.getpid()}.tmp")
        temporary.write_text(text)
        temporary.replace(path)
    return path
