"""Procedural space debris: small satellites, structural fragments and rocks, sized for a parallel gripper.

A small satellite is a bus (a 3.5-4.5 cm box) with up to two solar wings on yokes and up to two whip antennas;
a fragment is a flat, jagged convex shard of aluminium; rocks come from ``procgen.rock``. Every collision part
is convex and exact (boxes, cylinders, hulls); the visual solid is their boolean union, from which the mass
and inertia follow (one density per kind of debris).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import trimesh

from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart, box_mesh, cylinder_mesh
from mani_skill_space.procgen.rock import make_rock

DEBRIS_KINDS = ("satellite", "fragment", "rock")
DEBRIS_KIND_WEIGHTS = (0.5, 0.25, 0.25)
SATELLITE_DENSITY = 1330.0
"""A 1U CubeSat's 1.33 kg in 1 litre."""
FRAGMENT_DENSITY = 2700.0
BUS_SIZE = (0.035, 0.045)
"""Edge lengths (m): any way it turns, the bus fits between the Panda's fingers (8 cm apart when open)."""
GOLD_FOIL = (0.85, 0.66, 0.25, 1.0)
SOLAR_CELLS = (0.08, 0.12, 0.4, 1.0)
STRUCTURE = (0.75, 0.76, 0.78, 1.0)
ANTENNA = (0.85, 0.85, 0.82, 1.0)


def make_debris(seed: int) -> Asset:
    """A debris piece of a kind drawn from the seed (half satellites, a quarter each fragments and rocks)."""
    rng = np.random.default_rng([int(seed), 7])
    kind = DEBRIS_KINDS[rng.choice(len(DEBRIS_KINDS), p=DEBRIS_KIND_WEIGHTS)]
    return {"satellite": make_satellite, "fragment": make_fragment, "rock": make_debris_rock}[kind](seed)


def make_debris_rock(seed: int) -> Asset:
    rock = make_rock(seed, "lunar")
    return replace(rock, info={**rock.info, "kind": "rock"})


def make_satellite(seed: int) -> Asset:
    """A small satellite: a bus, 0-2 solar wings on yokes and 0-2 antennas, centred on its centre of mass."""
    rng = np.random.default_rng([int(seed), 11])
    half = rng.uniform(*BUS_SIZE, 3) / 2
    parts = [(box_mesh(half), GOLD_FOIL, 0.4, 0.7)]
    wing_axis = int(rng.integers(2))  # wings stick out along x or y
    for side in _wing_sides(rng):
        parts += _wing(rng, half, wing_axis, side)
    for _ in range(int(rng.integers(0, 3))):
        parts.append((_antenna(rng, half), ANTENNA, 0.5, 0.6))
    return _assemble(f"satellite_{seed}", parts, SATELLITE_DENSITY, {"kind": "satellite", "bus_size": (2 * half).tolist()})


def make_fragment(seed: int) -> Asset:
    """A jagged flat shard of structure, 3-7 cm across and 0.4-1 cm thick."""
    rng = np.random.default_rng([int(seed), 13])
    count = int(rng.integers(8, 16))
    angles = np.sort(rng.uniform(0, 2 * np.pi, count))
    radii = rng.uniform(0.015, 0.035, count)
    outline = np.stack([np.cos(angles) * radii, np.sin(angles) * radii], axis=1)
    thickness = rng.uniform(0.004, 0.01)
    points = np.concatenate([np.c_[outline, np.full(count, -thickness / 2)], np.c_[outline, np.full(count, thickness / 2)]])
    shard = trimesh.convex.convex_hull(points)
    return _assemble(f"fragment_{seed}", [(shard, STRUCTURE, 0.5, 0.8)], FRAGMENT_DENSITY, {"kind": "fragment"})


def _wing_sides(rng: np.random.Generator) -> tuple[float, ...]:
    return ((), (1.0,), (-1.0, 1.0))[int(rng.choice(3, p=(0.2, 0.3, 0.5)))]


def _wing(rng: np.random.Generator, half: np.ndarray, axis: int, side: float) -> list[tuple]:
    """A yoke and a thin solar panel sticking out of the bus along ``axis`` on ``side``."""
    span, chord, thickness = rng.uniform(0.04, 0.08), rng.uniform(0.8, 1.0) * 2 * half[2], 0.003
    yoke_length = 0.01
    direction = np.eye(3)[axis] * side
    yoke_centre = direction * (half[axis] + yoke_length / 2)
    yoke_half = np.full(3, 0.003)
    yoke_half[axis] = yoke_length / 2 + 0.001  # overlaps the bus a little so the union is one solid
    panel_centre = direction * (half[axis] + yoke_length + span / 2)
    panel_half = np.array([thickness / 2] * 3)
    panel_half[axis] = span / 2 + 0.001
    panel_half[2] = chord / 2
    return [(box_mesh(yoke_half, yoke_centre), STRUCTURE, 0.4, 0.8), (box_mesh(panel_half, panel_centre), SOLAR_CELLS, 0.3, 0.4)]


def _antenna(rng: np.random.Generator, half: np.ndarray) -> trimesh.Trimesh:
    """A whip antenna from a corner region of the bus's top face, along z."""
    length, radius = rng.uniform(0.03, 0.08), rng.uniform(0.0015, 0.0025)
    x, y = rng.uniform(-0.7, 0.7, 2) * half[:2]
    sign = rng.choice([-1.0, 1.0])
    return cylinder_mesh(radius, length + 0.002, 8, (x, y, sign * (half[2] + length / 2)))


def _assemble(name: str, parts: list[tuple], density: float, info: dict) -> Asset:
    meshes = [mesh for mesh, *_ in parts]
    solid = meshes[0].copy() if len(meshes) == 1 else trimesh.boolean.union(meshes, engine="manifold")
    centre = solid.center_mass
    for mesh in meshes:
        mesh.apply_translation(-centre)
    solid.apply_translation(-centre)
    return Asset(
        name=name,
        visual_parts=tuple(VisualPart(mesh, color, roughness=r, metallic=m) for mesh, color, r, m in parts),
        collision_parts=tuple(CollisionPart(mesh) for mesh in meshes),
        density=density,
        solid=solid,
        info={**info, "extents": solid.extents.tolist()},
    )
