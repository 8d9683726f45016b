"""A free-floating servicer: the arm's robot description on a spacecraft bus (sim-free).

``servicer_urdf`` adds a box-shaped bus as the robot's new root link, the arm's base fixed to the centre of its top
face, so that a simulator that does not fix the root link lets the whole servicer float: every arm motion then
moves and turns the bus (momentum is conserved, as for a real servicer). The bus's mass is the kwarg
``servicer_mass``, its inertia that of a uniform box of ``SERVICER_SIZE``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

BUS_LINK = "servicer_bus"
SERVICER_SIZE = (0.6, 0.6, 0.5)
"""m: the bus of a small servicer spacecraft (x, y, z)."""
ARM_SETBACK = 0.1
"""m: the arm stands on the bus's top face this far behind its front edge (on its centre line), so that the bus stays
clear of the parts in front of the arm (a lying peg reaches to 0.34 m in front of the arm)."""
DEFAULT_SERVICER_MASS = 150.0
SERVICER_MASS_RANGE = (10.0, 100_000.0)
"""kg: a bus lighter than this would be lighter than the arm's own links summed; heavier is a station."""
BUS_COLOR = "0.72 0.70 0.62 1"

MOUNTS = ("fixed", "free_flyer")
"""``mount`` kwarg: the arm on the station (or rover), or on a free-floating servicer (orbit only)."""


def check_servicer_mass(value) -> float:
    """The ``servicer_mass`` kwarg: a finite number of kg within ``SERVICER_MASS_RANGE`` (None gives the default)."""
    if value is None:
        return DEFAULT_SERVICER_MASS
    low, high = SERVICER_MASS_RANGE
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or not low <= value <= high:
        raise ValueError(f"servicer_mass must be a number of kg in [{low:g}, {high:g}], got {value!r}")
    return float(value)


def box_inertia(mass: float, size: tuple[float, float, float]) -> tuple[float, float, float]:
    """Principal moments (ixx, iyy, izz) of a uniform box of ``mass`` and edge lengths ``size`` about its centre."""
    x, y, z = size
    return mass * (y * y + z * z) / 12.0, mass * (x * x + z * z) / 12.0, mass * (x * x + y * y) / 12.0


def servicer_urdf(arm_urdf: str, arm_directory: Path, mass: float, size: tuple[float, float, float] = SERVICER_SIZE) -> str:
    """The URDF text of the arm (``arm_urdf``, whose mesh paths are relative to ``arm_directory``) standing on a bus
    of ``mass`` kg: a ``BUS_LINK`` root (its frame where the arm stands: on the box's top face, ``ARM_SETBACK``
    behind its front edge, x forward, z up) and a fixed joint to the arm's root link. Mesh paths become absolute, so the text may be written anywhere."""
    robot = ET.fromstring(arm_urdf)
    arm_root = _root_link(robot)
    for mesh in robot.iter("mesh"):
        filename = mesh.get("filename", "")
        if filename and "://" not in filename and not Path(filename).is_absolute():
            mesh.set("filename", str((Path(arm_directory) / filename).resolve()))
    robot.insert(0, _bus_link(mass, size))
    joint = ET.Element("joint", name=f"{BUS_LINK}_to_{arm_root}", type="fixed")
    ET.SubElement(joint, "parent", link=BUS_LINK)
    ET.SubElement(joint, "child", link=arm_root)
    ET.SubElement(joint, "origin", xyz="0 0 0", rpy="0 0 0")
    robot.insert(1, joint)
    return ET.tostring(robot, encoding="unicode")


def _root_link(robot: ET.Element) -> str:
    children = {child.get("link") for child in robot.iter("child")}
    roots = [link.get("name") for link in robot.findall("link") if link.get("name") not in children]
    if len(roots) != 1:
        raise ValueError(f"the robot description has {len(roots)} root links ({roots}); a servicer needs exactly one")
    return roots[0]


def _bus_link(mass: float, size: tuple[float, float, float]) -> ET.Element:
    centre = f"{-(size[0] / 2 - ARM_SETBACK):g} 0 {-size[2] / 2:g}"
    box = " ".join(f"{s:g}" for s in size)
    ixx, iyy, izz = box_inertia(mass, size)
    link = ET.Element("link", name=BUS_LINK)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "origin", xyz=centre, rpy="0 0 0")
    ET.SubElement(inertial, "mass", value=f"{mass:g}")
    ET.SubElement(inertial, "inertia", ixx=f"{ixx:g}", ixy="0", ixz="0", iyy=f"{iyy:g}", iyz="0", izz=f"{izz:g}")
    for tag in ("visual", "collision"):
        element = ET.SubElement(link, tag)
        ET.SubElement(element, "origin", xyz=centre, rpy="0 0 0")
        ET.SubElement(ET.SubElement(element, "geometry"), "box", size=box)
        if tag == "visual":
            ET.SubElement(ET.SubElement(element, "material", name="servicer_bus"), "color", rgba=BUS_COLOR)
    return link
