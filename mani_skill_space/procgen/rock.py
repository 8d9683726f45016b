"""Procedural rocks: a few overlapping convex chunks, so the convex decomposition is exact by construction.

The visual solid is the boolean union of the chunks (watertight, via manifold3d); the collision parts are the
chunks themselves, each a convex hull with at most 64 vertices (GPU-cookable). Lunar rocks are angular
breccia-like clusters; Martian rocks are rounder, wind-worn and flatter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart


@dataclass(frozen=True)
class RockFlavour:
    chunk_points: tuple[int, int]
    """Points sampled per chunk hull (fewer = more angular)."""
    radial_noise: float
    """Relative jitter of the sampled points' radius (rougher facets)."""
    extra_chunks: tuple[int, int]
    flatness: float
    """Height scale of the main chunk before normalisation."""
    colors: tuple[tuple[float, float, float], ...]
    roughness: float


ROCK_FLAVOURS: dict[str, RockFlavour] = {
    "lunar": RockFlavour(
        chunk_points=(14, 24),
        radial_noise=0.18,
        extra_chunks=(1, 3),
        flatness=0.8,
        colors=((0.42, 0.41, 0.39), (0.5, 0.49, 0.46), (0.35, 0.35, 0.34)),
        roughness=0.95,
    ),
    "martian": RockFlavour(
        chunk_points=(36, 56),
        radial_noise=0.06,
        extra_chunks=(0, 2),
        flatness=0.65,
        colors=((0.45, 0.25, 0.15), (0.52, 0.32, 0.2), (0.36, 0.22, 0.15)),
        roughness=0.85,
    ),
}

DEFAULT_ROCK_SIZE = (0.06, 0.06, 0.04)
ROCK_SIZE_JITTER = 0.1
"""Relative standard deviation of each bounding-box extent around the nominal size."""
ROCK_DENSITY = 2000.0


def make_rock(seed: int, flavour: str = "lunar", size=DEFAULT_ROCK_SIZE) -> Asset:
    """An irregular rock of about ``size`` (bounding-box extents in metres), centred on its centre of mass."""
    if flavour not in ROCK_FLAVOURS:
        raise ValueError(f"Unknown rock flavour {flavour!r}; valid choices: {', '.join(ROCK_FLAVOURS)}")
    style = ROCK_FLAVOURS[flavour]
    rng = np.random.default_rng([int(seed), list(ROCK_FLAVOURS).index(flavour)])

    chunks = _sample_chunks(rng, style)
    solid = _union(chunks)
    extents = np.asarray(size) * np.clip(rng.normal(1.0, ROCK_SIZE_JITTER, 3), 0.7, 1.3)
    scale = extents / solid.extents
    centre = solid.bounds.mean(axis=0)
    for mesh in [solid, *chunks]:
        mesh.apply_translation(-centre)
        mesh.apply_scale(scale)
    com = solid.center_mass
    for mesh in [solid, *chunks]:
        mesh.apply_translation(-com)

    color = np.asarray(style.colors[rng.integers(len(style.colors))]) * rng.uniform(0.9, 1.1)
    return Asset(
        name=f"rock_{flavour}_{seed}",
        visual_parts=(VisualPart(solid, (*np.clip(color, 0, 1), 1.0), roughness=style.roughness),),
        collision_parts=tuple(CollisionPart(c) for c in chunks),
        density=ROCK_DENSITY,
        info={"extents": solid.extents.copy(), "flavour": flavour},
    )


def _sample_chunks(rng: np.random.Generator, style: RockFlavour) -> list[trimesh.Trimesh]:
    main = _chunk(rng, style, centre=np.zeros(3), radii=np.array([1.0, rng.uniform(0.75, 1.0), style.flatness]))
    chunks = [main]
    for _ in range(rng.integers(style.extra_chunks[0], style.extra_chunks[1] + 1)):
        direction = _unit_vectors(rng, 1)[0] * np.array([1.0, 1.0, 0.6])
        radii = rng.uniform(0.35, 0.65) * np.array([1.0, rng.uniform(0.7, 1.0), rng.uniform(0.6, 0.9)])
        chunks.append(_chunk(rng, style, centre=direction * rng.uniform(0.55, 0.8), radii=radii))
    return chunks


def _chunk(rng: np.random.Generator, style: RockFlavour, centre: np.ndarray, radii: np.ndarray) -> trimesh.Trimesh:
    count = rng.integers(style.chunk_points[0], style.chunk_points[1] + 1)
    directions = _unit_vectors(rng, count)
    radius = 1.0 + rng.uniform(-style.radial_noise, style.radial_noise, (count, 1))
    points = centre + directions * radius * radii
    return trimesh.convex.convex_hull(points)


def _unit_vectors(rng: np.random.Generator, count: int) -> np.ndarray:
    v = rng.normal(size=(count, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _union(chunks: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    if len(chunks) == 1:
        return chunks[0].copy()
    return trimesh.boolean.union(chunks, engine="manifold")
