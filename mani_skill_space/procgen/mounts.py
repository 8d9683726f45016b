"""Structures that carry the arm: a planetary rover with a cargo bin, and an orbital station's work platform.

Built from boxes and cylinders, so every collision part is an exact convex primitive. World frame: origin on
the ground (or the platform's top) directly below the arm base, x forward, z up. The arm base sits 0.25 m above
that surface (the reference mount height), low enough for the Panda to pick objects off it in front of the
arm, and the base camera looks at the workspace from the same place on both mounts.
"""

from __future__ import annotations

import numpy as np

from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart, box_mesh, cylinder_mesh, look_at, translation_frame

ARM_MOUNT_HEIGHT = 0.25
DECK_HEIGHT = 0.20
CHASSIS_X = (-0.95, 0.25)
CHASSIS_HALF_WIDTH = 0.32
CHASSIS_THICKNESS = 0.10
WHEEL_RADIUS = 0.11
WHEEL_WIDTH = 0.08
WHEEL_X = (-0.78, -0.35, 0.08)
WHEEL_Y = 0.40
PEDESTAL_RADIUS = 0.075
PEDESTAL_GAP = 0.002
"""The pedestal stops just short of the arm base so the fixed base link never registers contact."""

BIN_CENTRE_XY = (-0.6, 0.0)
BIN_INNER_HALF_SIZE = (0.15, 0.17)
BIN_INNER_HEIGHT = 0.12
BIN_WALL = 0.012

BASE_CAMERA_EYE = (0.24, 0.0, 0.34)
BASE_CAMERA_POST_XY = (BASE_CAMERA_EYE[0] - 0.03, 0.0)
"""Where the base camera's post stands, horizontally from the arm's base (which is at the mount's origin)."""
BASE_CAMERA_POST_TOP = BASE_CAMERA_EYE[2] + 0.02 - ARM_MOUNT_HEIGHT
"""Height of the top of the base camera's head above the arm's base."""
BASE_CAMERA_TARGET = (0.62, 0.0, 0.0)

WHITE = (0.86, 0.86, 0.83, 1.0)
DARK = (0.13, 0.13, 0.14, 1.0)
GOLD = (0.83, 0.64, 0.25, 1.0)
ALUMINIUM = (0.72, 0.74, 0.77, 1.0)
SOLAR_BLUE = (0.1, 0.15, 0.45, 1.0)


def make_rover(wheel_sections: int = 20, cargo_bin: bool = True) -> Asset:
    """The rover: chassis, six wheels on side rails, arm pedestal, base-camera post and (unless ``cargo_bin`` is
    False, leaving its deck clear) the cargo bin.

    Frames: ``arm_mount`` (arm base), ``bin`` (centre of the bin's inner floor), ``base_camera`` (a look-at
    pose, SAPIEN camera convention: x forward, z up).
    """
    parts: list[tuple[object, tuple, float, float]] = []  # (mesh, colour, roughness, metallic)

    chassis_centre = ((CHASSIS_X[0] + CHASSIS_X[1]) / 2, 0.0, DECK_HEIGHT - CHASSIS_THICKNESS / 2)
    chassis_half = ((CHASSIS_X[1] - CHASSIS_X[0]) / 2, CHASSIS_HALF_WIDTH, CHASSIS_THICKNESS / 2)
    parts.append((box_mesh(chassis_half, chassis_centre), WHITE, 0.6, 0.0))
    parts.append((box_mesh((0.5, CHASSIS_HALF_WIDTH - 0.03, 0.004), (-0.3, 0.0, DECK_HEIGHT - 0.06)), GOLD, 0.4, 0.6))

    rail_x = (WHEEL_X[0] + WHEEL_X[-1]) / 2
    rail_half_length = (WHEEL_X[-1] - WHEEL_X[0]) / 2
    for side in (-1, 1):
        parts.append((box_mesh((rail_half_length, 0.02, 0.015), (rail_x, side * (WHEEL_Y - 0.05), WHEEL_RADIUS + 0.04)), DARK, 0.5, 0.3))
        for x in WHEEL_X:
            wheel = cylinder_mesh(WHEEL_RADIUS, WHEEL_WIDTH, wheel_sections, (x, side * WHEEL_Y, WHEEL_RADIUS), axis="y")
            parts.append((wheel, DARK, 0.9, 0.0))

    parts += _pedestal_and_camera(DECK_HEIGHT, wheel_sections)

    parts.append((box_mesh((0.065, 0.3, 0.05), (-0.87, 0.0, DECK_HEIGHT + 0.05)), GOLD, 0.4, 0.6))
    parts.append((box_mesh((0.012, 0.012, 0.15), (-0.87, 0.24, DECK_HEIGHT + 0.25)), DARK, 0.6, 0.2))
    parts.append((cylinder_mesh(0.06, 0.01, wheel_sections, (-0.87, 0.24, DECK_HEIGHT + 0.41)), WHITE, 0.5, 0.1))

    if cargo_bin:
        parts += [(mesh, ALUMINIUM, 0.35, 0.7) for mesh in _bin_meshes()]

    bin_floor = (BIN_CENTRE_XY[0], BIN_CENTRE_XY[1], DECK_HEIGHT + BIN_WALL)
    return Asset(
        name="rover",
        visual_parts=tuple(VisualPart(m, c, roughness=r, metallic=mt) for m, c, r, mt in parts),
        collision_parts=tuple(CollisionPart(m) for m, *_ in parts),
        frames={**_arm_frames(), "bin": translation_frame(bin_floor)},
        info={"bin_inner_half_size": (*BIN_INNER_HALF_SIZE, BIN_INNER_HEIGHT / 2), "bin_inner_height": BIN_INNER_HEIGHT},
    )


def _bin_meshes():
    """Floor and four walls of an open box resting on the deck."""
    cx, cy = BIN_CENTRE_XY
    hx, hy = BIN_INNER_HALF_SIZE
    w = BIN_WALL
    floor_z = DECK_HEIGHT + w / 2
    wall_z = DECK_HEIGHT + w + BIN_INNER_HEIGHT / 2
    wall_half_height = BIN_INNER_HEIGHT / 2
    yield box_mesh((hx + w, hy + w, w / 2), (cx, cy, floor_z))
    for side in (-1, 1):
        yield box_mesh((w / 2, hy + w, wall_half_height), (cx + side * (hx + w / 2), cy, wall_z))
        yield box_mesh((hx, w / 2, wall_half_height), (cx, cy + side * (hy + w / 2), wall_z))



PLATFORM_X = (-0.5, 0.95)
PLATFORM_HALF_WIDTH = 0.6
PLATFORM_THICKNESS = 0.04


def make_station() -> Asset:
    """A work platform on an orbital station's truss: the arm on a pedestal at its rear, its top at z = 0.

    The platform stands in for the ground: objects placed on it stay put in zero gravity. The truss boom,
    the station module and the solar wings behind it are visual only (nothing can reach them).
    """
    centre_x = (PLATFORM_X[0] + PLATFORM_X[1]) / 2
    half_length = (PLATFORM_X[1] - PLATFORM_X[0]) / 2
    solid = [(box_mesh((half_length, PLATFORM_HALF_WIDTH, PLATFORM_THICKNESS / 2), (centre_x, 0.0, -PLATFORM_THICKNESS / 2)), WHITE, 0.6, 0.1)]
    solid += _pedestal_and_camera(0.0, 20)
    decoration = []
    for y in (-0.45, 0.45):
        decoration.append((box_mesh((half_length, 0.03, 0.04), (centre_x, y, -PLATFORM_THICKNESS - 0.04)), ALUMINIUM, 0.4, 0.6))
    decoration.append((box_mesh((1.5, 0.06, 0.06), (PLATFORM_X[0] - 1.5, 0.0, -0.2)), ALUMINIUM, 0.4, 0.6))
    decoration.append((cylinder_mesh(0.6, 2.0, 24, (PLATFORM_X[0] - 3.6, 0.0, -0.2), axis="x"), WHITE, 0.5, 0.2))
    for side in (-1, 1):
        decoration.append((box_mesh((0.05, 0.05, 0.05), (PLATFORM_X[0] - 2.0, side * 0.1, -0.2)), DARK, 0.5, 0.2))
        decoration.append((box_mesh((0.8, 1.2, 0.01), (PLATFORM_X[0] - 2.0, side * 1.4, -0.2)), SOLAR_BLUE, 0.3, 0.5))
    return Asset(
        name="station",
        visual_parts=tuple(VisualPart(m, c, roughness=r, metallic=mt) for m, c, r, mt in solid + decoration),
        collision_parts=tuple(CollisionPart(m) for m, *_ in solid),
        frames=_arm_frames(),
    )


def _pedestal_and_camera(surface_height: float, sections: int) -> list[tuple]:
    """The arm's pedestal up to the mount height and the base camera on its post, standing on a surface."""
    pedestal_height = ARM_MOUNT_HEIGHT - surface_height - PEDESTAL_GAP
    pedestal = cylinder_mesh(PEDESTAL_RADIUS, pedestal_height, sections, (0.0, 0.0, surface_height + pedestal_height / 2))
    post_height = BASE_CAMERA_EYE[2] - surface_height - 0.02
    post = box_mesh((0.015, 0.015, post_height / 2), (BASE_CAMERA_POST_XY[0], BASE_CAMERA_POST_XY[1], surface_height + post_height / 2))
    head = box_mesh((0.02, 0.04, 0.02), (BASE_CAMERA_EYE[0] - 0.02, 0.0, BASE_CAMERA_EYE[2]))
    return [(pedestal, ALUMINIUM, 0.4, 0.6), (post, DARK, 0.6, 0.2), (head, DARK, 0.3, 0.2)]


def _arm_frames() -> dict[str, np.ndarray]:
    return {"arm_mount": translation_frame((0.0, 0.0, ARM_MOUNT_HEIGHT)), "base_camera": look_at(BASE_CAMERA_EYE, BASE_CAMERA_TARGET)}
