"""Saving and loading assets as a folder: ``asset.json`` plus one Wavefront OBJ file per mesh.

Dataset objects ship this way inside the package (``mani_skill_space/assets/dataset``). A folder may list
``"collision": "coacd"`` instead of collision parts; its convex parts are then computed (and cached) on load.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trimesh

from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart
from mani_skill_space.procgen.decomposition import convex_decomposition

MANIFEST = "asset.json"


def save_asset(asset: Asset, directory: str | Path) -> Path:
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    visuals = []
    for i, part in enumerate(asset.visual_parts):
        if part.texture is not None:
            raise ValueError(f"{asset.name}: textured visual parts are not supported in saved assets")
        name = f"visual_{i}.obj"
        _write_obj(part.mesh, directory / name)
        visuals.append(
            {"mesh": name, "color": list(part.color), "roughness": part.roughness, "metallic": part.metallic, "flat_shading": part.flat_shading}
        )
    collisions = []
    for i, part in enumerate(asset.collision_parts):
        name = f"collision_{i}.obj"
        _write_obj(part.mesh, directory / name)
        collisions.append({"mesh": name, "convex": part.convex})
    solid = None
    if asset.solid is not None:
        solid = "solid.obj"
        _write_obj(asset.solid, directory / solid)
    manifest = {
        "name": asset.name,
        "solid": solid,
        "density": asset.density,
        "friction": asset.friction,
        "visual_parts": visuals,
        "collision": collisions,
        "frames": {k: np.asarray(v).tolist() for k, v in asset.frames.items()},
        "info": _jsonable(dict(asset.info)),
    }
    (directory / MANIFEST).write_text(json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    return directory


def load_asset(directory: str | Path) -> Asset:
    directory = Path(directory)
    manifest = json.loads((directory / MANIFEST).read_text())
    visual_parts = tuple(
        VisualPart(
            _read_obj(directory / v["mesh"]),
            tuple(v["color"]),
            roughness=v.get("roughness", 0.8),
            metallic=v.get("metallic", 0.0),
            flat_shading=v.get("flat_shading", True),
        )
        for v in manifest["visual_parts"]
    )
    collision = manifest["collision"]
    if collision == "coacd":
        solid = trimesh.util.concatenate([p.mesh for p in visual_parts])
        collision_parts = tuple(CollisionPart(m) for m in convex_decomposition(solid))
    else:
        collision_parts = tuple(CollisionPart(_read_obj(directory / c["mesh"]), convex=c.get("convex", True)) for c in collision)
    return Asset(
        name=manifest["name"],
        visual_parts=visual_parts,
        collision_parts=collision_parts,
        density=manifest.get("density", 1000.0),
        friction=manifest.get("friction"),
        frames={k: np.asarray(v) for k, v in manifest.get("frames", {}).items()},
        info=manifest.get("info", {}),
        solid=_read_obj(directory / manifest["solid"]) if manifest.get("solid") else None,
    )


def _write_obj(mesh: trimesh.Trimesh, path: Path) -> None:
    mesh.export(path, file_type="obj", include_normals=False, include_color=False, include_texture=False, digits=7)


def _read_obj(path: Path) -> trimesh.Trimesh:
    return trimesh.load(path, file_type="obj", process=False, force="mesh", maintain_order=True)


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value
