"""The asset record every generator returns: visual parts, collision parts and named task frames."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Optional

import numpy as np
import trimesh

GPU_CONVEX_VERTEX_LIMIT = 64
"""PhysX cooks GPU-compatible convex hulls with at most 64 vertices."""


@dataclass(frozen=True)
class VisualPart:
    mesh: trimesh.Trimesh
    color: tuple[float, float, float, float]
    roughness: float = 0.8
    metallic: float = 0.0
    flat_shading: bool = True
    """Faceted look (per-face normals) instead of smooth vertex normals."""
    texture: Optional[str] = None
    """Name of a ground texture (``procgen.textures.GROUND_KINDS``) tiled by ``uv``."""
    uv: Optional[np.ndarray] = None


@dataclass(frozen=True)
class CollisionPart:
    mesh: trimesh.Trimesh
    convex: bool = True
    """False only for static triangle meshes (terrain); dynamic bodies use convex parts."""


@dataclass(frozen=True)
class Asset:
    """A generated or loaded object, in its own frame (metres).

    Dynamic objects are centred on their centre of mass. ``frames`` holds task frames as 4x4 poses in the
    asset frame (e.g. a hole entrance); ``info`` holds scalar facts (sizes, symmetry order, ...).
    """

    name: str
    visual_parts: tuple[VisualPart, ...]
    collision_parts: tuple[CollisionPart, ...]
    density: float = 1000.0
    friction: Optional[float] = None
    """Static and dynamic friction coefficient of the surfaces; None: the scene's default (1.0 here)."""
    frames: Mapping[str, np.ndarray] = field(default_factory=dict)
    info: Mapping[str, Any] = field(default_factory=dict)
    solid: Optional[trimesh.Trimesh] = None
    """The watertight solid the mass and inertia come from, where the coloured visual parts overlap; None:
    the visual mesh itself."""

    @property
    def visual_mesh(self) -> trimesh.Trimesh:
        meshes = [p.mesh for p in self.visual_parts]
        return meshes[0] if len(meshes) == 1 else trimesh.util.concatenate(meshes)

    @property
    def collision_vertices(self) -> np.ndarray:
        return np.concatenate([p.mesh.vertices for p in self.collision_parts])

    def mass_properties(self) -> tuple[float, np.ndarray, np.ndarray]:
        """Mass, centre of mass and inertia tensor (about the centre of mass) of the watertight solid.

        Overlapping convex collision parts would double-count mass, so dynamic bodies take their inertia
        from the visual solid instead.
        """
        mesh = self.solid if self.solid is not None else self.visual_mesh
        if not mesh.is_volume:
            raise ValueError(f"{self.name}: visual mesh is not a closed volume; cannot compute its mass")
        props = trimesh.triangles.mass_properties(mesh.triangles, density=self.density)
        return float(props.mass), np.asarray(props.center_mass), np.asarray(props.inertia)

    def scaled(self, factor: float) -> "Asset":
        """The asset ``factor`` times as large about its origin: meshes, solid and frame positions (``info`` keeps
        the generated sizes)."""

        def grown(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
            copy = mesh.copy()
            copy.apply_scale(factor)
            return copy

        frames = {}
        for name, frame in self.frames.items():
            frames[name] = np.array(frame, dtype=np.float64)
            frames[name][:3, 3] *= factor
        return replace(
            self,
            visual_parts=tuple(replace(part, mesh=grown(part.mesh)) for part in self.visual_parts),
            collision_parts=tuple(replace(part, mesh=grown(part.mesh)) for part in self.collision_parts),
            solid=None if self.solid is None else grown(self.solid),
            frames=frames,
        )


def box_mesh(half_size, center=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    mesh = trimesh.creation.box(extents=2 * np.asarray(half_size, dtype=np.float64))
    mesh.apply_translation(center)
    return mesh


def solid_difference(solid: trimesh.Trimesh, cavity: trimesh.Trimesh) -> trimesh.Trimesh:
    """``solid`` minus ``cavity`` with manifold3d, for meshes closed and outward-wound by construction (convex hulls,
    boxes): trimesh's check that each input is a volume is skipped (it took about two thirds of a hole module's cut:
    1.4-1.6 ms with it, 0.45 ms without)."""
    return trimesh.boolean.difference([solid, cavity], engine="manifold", check_volume=False)


def solid_union(meshes: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """The union of ``meshes`` with manifold3d, for meshes closed and outward-wound by construction (see
    ``solid_difference``)."""
    return trimesh.boolean.union(meshes, engine="manifold", check_volume=False)


def cylinder_mesh(radius: float, length: float, sections: int, center=(0.0, 0.0, 0.0), axis: str = "z") -> trimesh.Trimesh:
    mesh = trimesh.creation.cylinder(radius=radius, height=length, sections=sections)
    if axis == "x":
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    elif axis == "y":
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    mesh.apply_translation(center)
    return mesh


def translation_frame(position) -> np.ndarray:
    frame = np.eye(4)
    frame[:3, 3] = position
    return frame


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """4x4 pose at ``eye`` whose x axis points at ``target``, z axis as close to ``up`` as possible (SAPIEN camera convention)."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    forward = target - eye
    forward /= np.linalg.norm(forward)
    left = np.cross(up, forward)
    left /= np.linalg.norm(left)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([forward, left, np.cross(forward, left)], axis=1)
    pose[:3, 3] = eye
    return pose
