"""SAPIEN wiring: turn sim-free ``Asset`` records into ManiSkill actors, the ManiSkill way.

Meshes go straight from arrays into SAPIEN render shapes and PhysX collision shapes (no files). Assets that
differ per parallel env are built one per sub-scene with ``set_scene_idxs([i])`` and merged into one batched
``Actor`` view, as ManiSkill's PickSingleYCB and PegInsertionSide do.
"""

from __future__ import annotations

import functools
from typing import Optional, Sequence

import numpy as np
import sapien
import sapien.physx as physx
import sapien.render
import torch
from mani_skill.envs.scene import ManiSkillScene
from mani_skill.utils.building.actor_builder import ActorBuilder
from mani_skill.utils.structs import Actor

from mani_skill_space.dataset import ground_texture_path
from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart
from mani_skill_space.procgen.skydome import make_skydome_mesh

SKYDOME_RADIUS = 15.0
"""Inside every camera's far plane (25 m) and far beyond the terrain (4 m), so it reads as the sky."""


class AssetActorBuilder(ActorBuilder):
    """ManiSkill's ``ActorBuilder`` that also takes the visual and collision parts of an ``Asset``."""

    def __init__(self):
        super().__init__()
        self._mesh_visuals: list[VisualPart] = []
        self._mesh_collisions: list[tuple[CollisionPart, float, physx.PhysxMaterial]] = []

    def add_asset(self, asset: Asset, with_mass: bool = True):
        self._mesh_visuals.extend(asset.visual_parts)
        material = physx.get_default_material() if asset.friction is None else physx.PhysxMaterial(asset.friction, asset.friction, 0.0)
        self._mesh_collisions.extend((part, asset.density, material) for part in asset.collision_parts)
        if with_mass:
            mass, com, inertia = asset.mass_properties()
            principal, axes = np.linalg.eigh(inertia)
            if np.linalg.det(axes) < 0:
                axes[:, 0] = -axes[:, 0]
            self.set_mass_and_inertia(mass, sapien.Pose(com, _matrix_to_quaternion(axes)), principal)
        return self

    def build_entity(self):
        entity = sapien.Entity()
        if self.scene.can_render() and (self.visual_records or self._procedural_shapes or self._mesh_visuals):
            entity.add_component(self.build_render_component())
        entity.add_component(self.build_physx_component())
        entity.name = self.name
        return entity

    def build_render_component(self):
        component = super().build_render_component()
        for shape in self._procedural_shapes:
            component.attach(shape)
        for part in self._mesh_visuals:
            component.attach(render_shape(part))
        return component

    def build_physx_component(self, link_parent=None):
        component = super().build_physx_component(link_parent)
        for part, density, material in self._mesh_collisions:
            shape = collision_shape(part, material)
            shape.set_collision_groups(self.collision_groups)
            shape.set_density(density)
            component.attach(shape)
        if not self._auto_inertial and self.physx_body_type == "dynamic":
            # Attaching shapes after the base class applied the explicit mass would let PhysX recompute it.
            component.mass = self._mass
            component.cmass_local_pose = self._cmass_local_pose
            component.inertia = self._inertia
        return component


def render_shape(part: VisualPart) -> sapien.render.RenderShapeTriangleMesh:
    mesh = part.mesh
    if part.flat_shading:
        vertices = mesh.vertices[mesh.faces].reshape(-1, 3)
        triangles = np.arange(len(vertices)).reshape(-1, 3)
        normals = np.repeat(mesh.face_normals, 3, axis=0)
        uvs = np.zeros((len(vertices), 2)) if part.uv is None else part.uv[mesh.faces].reshape(-1, 2)
    else:
        vertices, triangles, normals = mesh.vertices, mesh.faces, mesh.vertex_normals
        uvs = np.zeros((len(vertices), 2)) if part.uv is None else part.uv
    material = sapien.render.RenderMaterial(base_color=list(part.color), roughness=part.roughness, metallic=part.metallic)
    if part.texture is not None:
        material.base_color_texture = _texture(str(ground_texture_path(part.texture)))
    return sapien.render.RenderShapeTriangleMesh(
        vertices=np.ascontiguousarray(vertices, dtype=np.float32),
        triangles=np.ascontiguousarray(triangles, dtype=np.uint32),
        normals=np.ascontiguousarray(normals, dtype=np.float32),
        uvs=np.ascontiguousarray(uvs, dtype=np.float32),
        material=material,
    )


def collision_shape(part: CollisionPart, material: physx.PhysxMaterial):
    vertices = np.ascontiguousarray(part.mesh.vertices, dtype=np.float32)
    scale = np.ones(3, dtype=np.float32)
    if part.convex:
        return physx.PhysxCollisionShapeConvexMesh(vertices=vertices, scale=scale, material=material)
    triangles = np.ascontiguousarray(part.mesh.faces, dtype=np.uint32)
    return physx.PhysxCollisionShapeTriangleMesh(vertices=vertices, triangles=triangles, scale=scale, material=material)


@functools.lru_cache(maxsize=None)
def _texture(path: str) -> sapien.render.RenderTexture2D:
    return sapien.render.RenderTexture2D(filename=path, mipmap_levels=4)


def build_asset_actor(
    scene: ManiSkillScene,
    asset: Asset,
    name: str,
    body_type: str = "dynamic",
    initial_pose: Optional[sapien.Pose] = None,
    scene_idxs: Optional[Sequence[int]] = None,
) -> Actor:
    builder = AssetActorBuilder()
    builder.set_scene(scene)
    builder.add_asset(asset, with_mass=body_type == "dynamic")
    builder.initial_pose = initial_pose or sapien.Pose()
    if scene_idxs is not None:
        builder.set_scene_idxs(scene_idxs)
    builder.set_physx_body_type(body_type)
    return builder.build(name=name)


def build_actor_per_env(
    scene: ManiSkillScene, assets: Sequence[Asset], name: str, body_type: str = "dynamic", initial_pose: Optional[sapien.Pose] = None
) -> Actor:
    """One actor per sub-scene (``assets[i]`` in env ``i``), merged into a single batched view named ``name``."""
    if len(assets) != scene.num_envs:
        raise ValueError(f"{name}: need one asset per env ({scene.num_envs}), got {len(assets)}")
    parts = [build_asset_actor(scene, asset, f"{name}-{i}", body_type, initial_pose, scene_idxs=[i]) for i, asset in enumerate(assets)]
    for part in parts:
        scene.remove_from_state_dict_registry(part)
    merged = Actor.merge(parts, name=name)
    scene.add_to_state_dict_registry(merged)
    return merged


def bounding_radius(assets: Sequence[Asset]) -> float:
    """The largest distance from an asset's origin to its collision geometry, over ``assets`` (m)."""
    return max(float(np.linalg.norm(asset.collision_vertices, axis=1).max()) for asset in assets)


def build_dynamic_per_env(scene: ManiSkillScene, assets: Sequence[Asset], name: str) -> Actor:
    """Per-env dynamic objects (``assets[i]`` in env ``i``) placed out of the way; ``_initialize_episode`` poses them."""
    return build_actor_per_env(scene, assets, name, body_type="dynamic", initial_pose=sapien.Pose(p=[0, 0, 2.0]))


def build_skydome(scene: ManiSkillScene, texture_path: str, name: str = "skydome") -> Actor:
    """A visual-only inverted sphere whose emissive texture is the sky (cheap on CPU, unlike HDR maps)."""
    vertices, triangles, normals, uvs = make_skydome_mesh(SKYDOME_RADIUS)
    material = sapien.render.RenderMaterial(base_color=[0.0, 0.0, 0.0, 1.0], emission=[1.0, 1.0, 1.0, 1.0])
    material.emission_texture = _texture(texture_path)
    builder = scene.create_actor_builder()
    builder._procedural_shapes.append(
        sapien.render.RenderShapeTriangleMesh(vertices=vertices, triangles=triangles, normals=normals, uvs=uvs, material=material)
    )
    builder.initial_pose = sapien.Pose()
    return builder.build_kinematic(name=name)


def build_flat_ground(scene: ManiSkillScene, ground: Asset, name: str = "ground") -> Actor:
    """``ground``'s visual on an infinite collision plane at z = 0 (plain ground, e.g. on Earth)."""
    builder = AssetActorBuilder()
    builder.set_scene(scene)
    builder.add_asset(ground, with_mass=False)
    builder.add_plane_collision(sapien.Pose(p=[0, 0, 0], q=[0.7071068, 0, -0.7071068, 0]))
    builder.initial_pose = sapien.Pose()
    return builder.build_static(name=name)


def _matrix_to_quaternion(matrix: np.ndarray) -> np.ndarray:
    """wxyz quaternion of a proper rotation matrix."""
    return sapien.Pose(_homogeneous(matrix)).q


def _homogeneous(rotation: np.ndarray) -> np.ndarray:
    transform = np.eye(4)
    transform[:3, :3] = rotation
    return transform


def padded_points(point_sets: Sequence[np.ndarray], device) -> torch.Tensor:
    """Stack point sets of different sizes into (n, max_points, 3), padding by repeating each set's first point."""
    size = max(len(p) for p in point_sets)
    padded = np.stack([np.concatenate([p, np.repeat(p[:1], size - len(p), axis=0)]) for p in point_sets])
    return torch.as_tensor(padded, dtype=torch.float32, device=device)
