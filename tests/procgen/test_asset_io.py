import json

import numpy as np
import pytest
import trimesh

from mani_skill_space.procgen.asset import Asset, VisualPart
from mani_skill_space.procgen.asset_io import load_asset, save_asset
from mani_skill_space.procgen.mounts import make_rover


def test_saved_asset_loads_back_identically(tmp_path):
    rover = make_rover()
    loaded = load_asset(save_asset(rover, tmp_path / "rover"))
    assert loaded.name == rover.name
    for a, b in zip(rover.visual_parts + rover.collision_parts, loaded.visual_parts + loaded.collision_parts):
        np.testing.assert_allclose(a.mesh.vertices, b.mesh.vertices, atol=1e-6)
        np.testing.assert_array_equal(a.mesh.faces, b.mesh.faces)
    for name, frame in rover.frames.items():
        np.testing.assert_allclose(loaded.frames[name], frame)
    assert loaded.visual_parts[0].color == rover.visual_parts[0].color


def test_asset_listing_coacd_gets_its_convex_parts_computed_on_load(tmp_path):
    a = trimesh.creation.box(extents=[0.1, 0.02, 0.02])
    b = trimesh.creation.box(extents=[0.02, 0.08, 0.02])
    b.apply_translation([0.04, 0.03, 0])
    solid = trimesh.boolean.union([a, b], engine="manifold")
    folder = save_asset(Asset("user_object", (VisualPart(solid, (1, 0, 0, 1)),), ()), tmp_path / "user_object")
    manifest = json.loads((folder / "asset.json").read_text())
    manifest["collision"] = "coacd"
    (folder / "asset.json").write_text(json.dumps(manifest))
    loaded = load_asset(folder)
    assert len(loaded.collision_parts) >= 2
    assert all(p.convex for p in loaded.collision_parts)


def test_textured_parts_cannot_be_saved(tmp_path):
    mesh = trimesh.creation.box()
    part = VisualPart(mesh, (1, 1, 1, 1), texture="lunar_regolith", uv=np.zeros((8, 2)))
    with pytest.raises(ValueError, match="textured"):
        save_asset(Asset("x", (part,), ()), tmp_path)
