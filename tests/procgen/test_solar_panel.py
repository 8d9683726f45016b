import manifold3d
import numpy as np
import pytest
import trimesh

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.procgen.asset import GPU_CONVEX_VERTEX_LIMIT
from mani_skill_space.procgen.solar_panel import (
    LONG_SOCKETS,
    PEG_LENGTH_STEP,
    SEAT_HEIGHT,
    dataset_layout,
    make_panel,
    make_socket_base,
    make_solar_layout,
    make_solar_pegs,
)

SEEDS = range(8)


def _manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    return manifold3d.Manifold(manifold3d.Mesh(vert_properties=np.asarray(mesh.vertices, np.float32), tri_verts=np.asarray(mesh.faces, np.uint32)))


def _overlap(mesh: trimesh.Trimesh, parts) -> float:
    solid = _manifold(mesh)
    return sum((solid ^ _manifold(p.mesh)).volume() for p in parts)


def _placed(asset, frame: np.ndarray, goal: np.ndarray) -> trimesh.Trimesh:
    """The asset's (single) collision solid moved so that its ``frame`` lands on ``goal``."""
    mesh = asset.collision_parts[0].mesh.copy()
    mesh.apply_transform(goal @ np.linalg.inv(frame))
    return mesh


def _layouts():
    return [("procedural", make_solar_layout(seed), seed) for seed in SEEDS] + [("dataset", dataset_layout(0.1, 0.02, 0.001, 0.02), 0)]


def test_same_seed_same_bytes():
    a, b = make_solar_layout(3), make_solar_layout(3)
    assert a == b
    assert np.array_equal(make_socket_base(a).collision_vertices, make_socket_base(b).collision_vertices)
    assert np.array_equal(make_panel(a).collision_vertices, make_panel(b).collision_vertices)
    assert make_solar_layout(4) != a


@pytest.mark.parametrize("seed", SEEDS)
def test_procedural_ranges(seed):
    layout = make_solar_layout(seed)
    assert 0.010 <= layout.profile.radius <= 0.016
    assert 0.09 <= layout.short_length <= 0.12 and layout.long_length == pytest.approx(layout.short_length + PEG_LENGTH_STEP)
    assert 0.02 <= layout.depth <= 0.03
    assert all(0.9 <= s <= 1.1 for s in layout.panel_scale)
    pegs = make_solar_pegs(layout, seed)
    lengths = [p.info["height"] for p in pegs]
    assert lengths == [layout.long_length if i in LONG_SOCKETS else layout.short_length for i in range(4)]
    assert all(p.info["symmetry_order"] == layout.profile.symmetry_order for p in pegs)


@pytest.mark.parametrize("source, layout, seed", _layouts())
def test_socket_pieces_are_the_posts_minus_their_bores(source, layout, seed):
    base = make_socket_base(layout)
    assert all(p.convex and len(p.mesh.vertices) <= GPU_CONVEX_VERTEX_LIMIT for p in base.collision_parts)
    solid_volume = sum(v.mesh.volume for v in base.visual_parts)
    assert sum(p.mesh.volume for p in base.collision_parts) == pytest.approx(solid_volume, rel=0.01)


@pytest.mark.parametrize("source, layout, seed", _layouts())
def test_inserted_pegs_fit_their_sockets_and_stand_level(source, layout, seed):
    base = make_socket_base(layout)
    if source == "dataset":
        pegs = [load_dataset_object("profile_peg_long" if i in LONG_SOCKETS else "profile_peg_short") for i in range(4)]
    else:
        pegs = make_solar_pegs(layout, seed)
    for i, peg in enumerate(pegs):
        bottom = base.frames[f"bottom_{i}"]
        assert bottom[2, 3] + peg.info["height"] == pytest.approx(SEAT_HEIGHT)
        assert base.frames[f"entrance_{i}"][2, 3] - bottom[2, 3] == pytest.approx(layout.depth)
        home = bottom.copy()
        home[2, 3] += 1e-5
        assert _overlap(_placed(peg, peg.frames["end_0"], home), base.collision_parts) < 1e-12
        # pushed a few clearances sideways it hits the socket's wall (a sharp profile's mitred bore corners
        # leave more room than the clearance toward them)
        for direction in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            shifted = home.copy()
            shifted[:2, 3] += 5 * layout.clearance * np.array(direction)
            assert _overlap(_placed(peg, peg.frames["end_0"], shifted), base.collision_parts) > 1e-9


@pytest.mark.parametrize("source, layout, seed", _layouts())
def test_panel_seats_over_the_inserted_pegs(source, layout, seed):
    base = make_socket_base(layout)
    panel = make_panel(layout)
    assert panel.solid.is_volume
    mass = panel.mass_properties()[0]
    assert 0.3 < mass < 0.8
    assert all(p.convex and len(p.mesh.vertices) <= GPU_CONVEX_VERTEX_LIMIT for p in panel.collision_parts)
    pegs = make_solar_pegs(layout, seed)
    seat_goal = np.eye(4)
    seat_goal[2, 3] = SEAT_HEIGHT + 1e-5
    panel_mesh = trimesh.util.concatenate([p.mesh for p in panel.collision_parts])
    panel_mesh.apply_transform(seat_goal @ np.linalg.inv(panel.frames["seat"]))
    for i, peg in enumerate(pegs):
        inserted = _placed(peg, peg.frames["end_0"], base.frames[f"bottom_{i}"])
        for part in panel.collision_parts:
            moved = part.mesh.copy()
            moved.apply_transform(seat_goal @ np.linalg.inv(panel.frames["seat"]))
            assert (_manifold(inserted) ^ _manifold(moved)).volume() < 1e-12
    # a centimetre off to the side, a receptacle's wall sits on a peg
    off = seat_goal.copy()
    off[0, 3] += 0.01 + layout.circumradius
    inserted = _placed(pegs[0], pegs[0].frames["end_0"], base.frames["bottom_0"])
    parts = [p.mesh.copy() for p in panel.collision_parts]
    for m in parts:
        m.apply_transform(off @ np.linalg.inv(panel.frames["seat"]))
    assert sum((_manifold(inserted) ^ _manifold(m)).volume() for m in parts) > 1e-9


def test_dataset_layout_matches_the_dataset_pegs():
    layout = dataset_layout(0.1, 0.02, 0.001, 0.02)
    assert layout.short_length == load_dataset_object("profile_peg_short").info["height"]
    assert layout.long_length == pytest.approx(load_dataset_object("profile_peg_long").info["height"])
    assert layout.circumradius == pytest.approx(0.01 * np.sqrt(2))
