"""Procedural regolith terrain: a heightfield with rolling noise, craters, dunes and boulders, and an exactly
flat disc around the robot so that the workspace is level.

The collision geometry is the heightfield's own triangle mesh (a static body), so it is exact.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy import ndimage

from mani_skill_space.domains import TerrainStyle
from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart

TERRAIN_HALF_EXTENT = 4.0
TERRAIN_RESOLUTION = 0.1
FLAT_RADIUS = 1.3
FLAT_BLEND = 0.7
TEXTURE_TILES_PER_METRE = 1.0


def make_terrain(
    seed: int,
    style: TerrainStyle,
    half_extent: float = TERRAIN_HALF_EXTENT,
    resolution: float = TERRAIN_RESOLUTION,
    flat_radius: float = FLAT_RADIUS,
) -> Asset:
    """Square terrain patch centred on the origin; z = 0 inside ``flat_radius`` of the origin."""
    rng = np.random.default_rng(int(seed))
    count = int(round(2 * half_extent / resolution)) + 1
    axis = np.linspace(-half_extent, half_extent, count)
    x, y = np.meshgrid(axis, axis, indexing="xy")
    radius = np.hypot(x, y)

    height = _fractal_noise(rng, count, half_extent, style.roughness_wavelength) * style.roughness_amplitude
    if style.dune_amplitude:
        height += _dunes(rng, x, y, style.dune_amplitude)
    height += _craters(rng, x, y, style, flat_radius)
    height += _boulders(rng, x, y, style.boulder_count, flat_radius)
    height *= _smoothstep((radius - flat_radius) / FLAT_BLEND)

    mesh = _grid_mesh(x, y, height)
    uv = np.stack([x.ravel(), y.ravel()], axis=1) * TEXTURE_TILES_PER_METRE
    visual = VisualPart(mesh, (1.0, 1.0, 1.0, 1.0), roughness=1.0, flat_shading=False, texture=style.texture, uv=uv)
    return Asset(
        name=f"terrain_{style.texture}_{seed}",
        visual_parts=(visual,),
        collision_parts=(CollisionPart(mesh, convex=False),),
        info={"half_extent": half_extent, "flat_radius": flat_radius},
    )


def make_flat_ground(texture: str, half_extent: float = TERRAIN_HALF_EXTENT) -> Asset:
    """Plain level ground (visual only: the env gives it an infinite collision plane, cheaper than a mesh)."""
    axis = np.array([-half_extent, half_extent])
    x, y = np.meshgrid(axis, axis, indexing="xy")
    mesh = _grid_mesh(x, y, np.zeros_like(x))
    uv = np.stack([x.ravel(), y.ravel()], axis=1) * TEXTURE_TILES_PER_METRE
    visual = VisualPart(mesh, (1.0, 1.0, 1.0, 1.0), roughness=1.0, flat_shading=False, texture=texture, uv=uv)
    return Asset(name=f"ground_{texture}", visual_parts=(visual,), collision_parts=(), info={"half_extent": half_extent})


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _fractal_noise(rng: np.random.Generator, count: int, half_extent: float, wavelength: float, octaves: int = 4) -> np.ndarray:
    """Sum of octaves of smoothly interpolated random lattices, zero-mean, roughly unit amplitude."""
    total = np.zeros((count, count))
    amplitude = 1.0
    for _ in range(octaves):
        cells = max(2, int(np.ceil(2 * half_extent / wavelength)) + 1)
        lattice = rng.normal(size=(cells, cells))
        total += amplitude * ndimage.zoom(lattice, count / cells, order=3, mode="nearest")[:count, :count]
        amplitude *= 0.5
        wavelength *= 0.5
    return total


def _dunes(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, amplitude: float) -> np.ndarray:
    heading = rng.uniform(0, np.pi)
    along = x * np.cos(heading) + y * np.sin(heading)
    wavelength = rng.uniform(1.5, 2.5)
    phase = rng.uniform(0, 2 * np.pi)
    return amplitude * 0.5 * (1 + np.sin(2 * np.pi * along / wavelength + phase + 0.4 * np.sin(y * 0.7)))


def _craters(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, style: TerrainStyle, flat_radius: float) -> np.ndarray:
    """Bowl-shaped depressions with raised rims, centred outside the flat disc."""
    height = np.zeros_like(x)
    half_extent = float(x.max())
    for _ in range(rng.integers(style.crater_count[0], style.crater_count[1] + 1)):
        r = rng.uniform(*style.crater_radius)
        distance = rng.uniform(flat_radius + 0.5 * r, half_extent)
        angle = rng.uniform(0, 2 * np.pi)
        rho = np.hypot(x - distance * np.cos(angle), y - distance * np.sin(angle)) / r
        depth = 0.22 * r
        rim = 0.25 * depth
        bowl = depth * (rho**2 - 1) + rim
        skirt = rim * np.exp(-(((rho - 1) / 0.35) ** 2))
        height += np.where(rho < 1, bowl, skirt)
    return height


def _boulders(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, count: int, flat_radius: float) -> np.ndarray:
    height = np.zeros_like(x)
    half_extent = float(x.max())
    for _ in range(count):
        distance = rng.uniform(flat_radius + 0.3, half_extent)
        angle = rng.uniform(0, 2 * np.pi)
        size = rng.uniform(0.1, 0.3)
        d2 = (x - distance * np.cos(angle)) ** 2 + (y - distance * np.sin(angle)) ** 2
        height = np.maximum(height, rng.uniform(0.4, 0.8) * size * np.exp(-d2 / size**2))
    return height


def _grid_mesh(x: np.ndarray, y: np.ndarray, height: np.ndarray) -> trimesh.Trimesh:
    rows, cols = x.shape
    vertices = np.stack([x.ravel(), y.ravel(), height.ravel()], axis=1)
    idx = np.arange(rows * cols).reshape(rows, cols)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, d], axis=1), np.stack([a, d, c], axis=1)])
    return trimesh.Trimesh(vertices, faces, process=False)
