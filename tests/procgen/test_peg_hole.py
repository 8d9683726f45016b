import manifold3d
import numpy as np
import pytest
import trimesh

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.procgen.asset import GPU_CONVEX_VERTEX_LIMIT
from mani_skill_space.procgen.peg_hole import (
    FINGER_ROOM,
    MAX_OFFSET,
    MAX_TILT,
    MODULE_HALF_SIZE,
    MODULE_HEIGHT,
    PegProfile,
    make_hole_module,
    make_peg,
    make_peg_hole_pair,
    peg_points,
    sample_profile,
)
from mani_skill_space.procgen.polytope import convex_mesh, subtract_convex, subtract_convex_meshes

SEEDS = range(20)


def _manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    return manifold3d.Manifold(manifold3d.Mesh(vert_properties=np.asarray(mesh.vertices, np.float32), tri_verts=np.asarray(mesh.faces, np.uint32)))


def _overlap(mesh: trimesh.Trimesh, parts) -> float:
    """Volume (m^3) shared by ``mesh`` and the collision ``parts``."""
    solid = _manifold(mesh)
    return sum((solid ^ _manifold(p.mesh)).volume() for p in parts)


def _peg_at(peg, hole, height: float, grow: float = 0.0, shift=(0.0, 0.0)) -> trimesh.Trimesh:
    """The peg's collision solid with its tip frame on the hole's axis ``height`` above the bottom."""
    tip, bottom = peg.frames["end_0"], hole.frames["bottom"]
    goal = bottom.copy()
    goal[:3, 3] += bottom[:3, :3] @ np.array([shift[0], shift[1], height])
    mesh = peg.collision_parts[0].mesh.copy()
    if grow:
        mesh = convex_mesh(mesh.vertices + grow * (mesh.vertices - mesh.vertices.mean(axis=0)) / np.linalg.norm(mesh.vertices - mesh.vertices.mean(axis=0), axis=1, keepdims=True))
    mesh.apply_transform(goal @ np.linalg.inv(tip))
    return mesh


@pytest.mark.parametrize("seed", SEEDS)
def test_hole_pieces_fill_exactly_the_module_outside_the_bore(seed):
    _, hole = make_peg_hole_pair(seed)
    block = 4 * MODULE_HALF_SIZE**2 * MODULE_HEIGHT
    visual = hole.visual_mesh
    assert visual.is_watertight
    pieces = sum(p.mesh.volume for p in hole.collision_parts)
    assert abs(pieces - visual.volume) / visual.volume < 0.01
    assert visual.volume < block  # something was cut out
    for part in hole.collision_parts:
        assert part.mesh.is_convex and len(part.mesh.vertices) <= GPU_CONVEX_VERTEX_LIMIT


@pytest.mark.parametrize("seed", SEEDS)
def test_the_peg_slides_down_the_bore_with_clearance_and_a_wider_peg_does_not(seed):
    peg, hole = make_peg_hole_pair(seed)
    depth = hole.info["depth"]
    for height in np.linspace(0.0, depth + 0.01, 6):
        assert _overlap(_peg_at(peg, hole, height), hole.collision_parts) < 1e-9, height
    clearance = hole.info["clearance"]
    assert _overlap(_peg_at(peg, hole, 0.0, grow=2 * clearance), hole.collision_parts) > 1e-8  # negative clearance
    assert _overlap(_peg_at(peg, hole, 0.0, shift=(3 * clearance, 0.0)), hole.collision_parts) > 1e-8
    assert _overlap(_peg_at(peg, hole, -0.002), hole.collision_parts) > 1e-9  # the bore has a floor


def test_no_piece_enters_the_bore():
    profile = sample_profile(np.random.default_rng(3))
    cavity = peg_points(profile, grow=0.001, extend=0.3, bore=True) + np.array([0.0, 0.0, 0.05])
    block = np.array([[x, y, z] for x in (-0.075, 0.075) for y in (-0.075, 0.075) for z in (0.0, 0.12)])
    pieces = subtract_convex(block, cavity)
    bore = _manifold(convex_mesh(cavity))
    for piece in pieces:
        assert (bore ^ _manifold(convex_mesh(piece))).volume() < 1e-12
    assert sum(convex_mesh(p).volume for p in pieces) == pytest.approx(convex_mesh(block).volume - (bore ^ _manifold(convex_mesh(block))).volume(), rel=1e-6)



@pytest.mark.parametrize("seed", range(6))
def test_the_pieces_as_meshes_are_the_hulls_of_the_pieces_exactly(seed):
    """``subtract_convex_meshes`` reuses the hull that sized each piece; the meshes must be ``convex_mesh``'s to the bit
    (the env's collision geometry, and the arm-planning verdicts cached under it, depend on them)."""
    profile = sample_profile(np.random.default_rng(seed))
    cavity = peg_points(profile, grow=0.001, extend=0.3, bore=True) + np.array([0.01, -0.02, 0.05])
    block = np.array([[x, y, z] for x in (-0.075, 0.075) for y in (-0.075, 0.075) for z in (0.0, 0.12)])
    meshes = subtract_convex_meshes(block, cavity)
    pieces = subtract_convex(block, cavity)
    assert len(meshes) == len(pieces) > 4
    for mesh, piece in zip(meshes, pieces):
        expected = convex_mesh(piece)
        assert np.array_equal(mesh.vertices, expected.vertices) and np.array_equal(mesh.faces, expected.faces)


@pytest.mark.parametrize("seed", SEEDS)
def test_hole_frames_follow_the_sampled_offset_tilt_and_depth(seed):
    peg, hole = make_peg_hole_pair(seed)
    entrance, bottom = hole.frames["entrance"], hole.frames["bottom"]
    depth, height = hole.info["depth"], peg.info["height"]
    assert entrance[2, 3] == pytest.approx(MODULE_HEIGHT)
    assert np.all(np.abs(entrance[:2, 3]) <= MAX_OFFSET + 1e-9)
    np.testing.assert_allclose(entrance[:3, :3], bottom[:3, :3])
    np.testing.assert_allclose(entrance[:3, 3] - depth * entrance[:3, 2], bottom[:3, 3], atol=1e-12)
    assert np.arccos(entrance[2, 2]) <= np.sqrt(2) * MAX_TILT + 1e-9
    assert 0.0 < depth <= max(0.25 * height, height - FINGER_ROOM) + 1e-12
    assert depth >= min(0.25 * height, height - FINGER_ROOM) - 1e-12


def test_symmetry_order_of_profiles():
    def profile(sides, circle=False, aspect=1.0):
        return PegProfile(sides=sides, circle=circle, radius=0.02, height=0.06, taper=0.1, aspect=aspect, aspect_angle=0.3)

    assert profile(32, circle=True).symmetry_order == 0
    assert profile(5).symmetry_order == 5
    assert profile(6, aspect=0.5).symmetry_order == 2
    assert profile(32, circle=True, aspect=0.5).symmetry_order == 2
    assert profile(5, aspect=0.5).symmetry_order == 1


def test_peg_is_one_exact_convex_part_with_its_tip_at_the_narrow_end():
    profile = PegProfile(sides=6, circle=False, radius=0.02, height=0.06, taper=0.2, aspect=1.0, aspect_angle=0.0)
    peg = make_peg(profile)
    (part,) = peg.collision_parts
    assert part.mesh is peg.visual_mesh or np.allclose(part.mesh.vertices, peg.visual_mesh.vertices)
    assert part.mesh.is_convex and len(part.mesh.vertices) == 12
    np.testing.assert_allclose(peg.visual_mesh.center_mass, 0.0, atol=1e-12)
    tip = peg.frames["end_0"]
    verts = part.mesh.vertices - tip[:3, 3]
    along = verts @ tip[:3, 2]
    assert along.min() == pytest.approx(0.0, abs=1e-12) and along.max() == pytest.approx(0.06)
    width = lambda h: np.ptp(verts[np.isclose(along, h)] @ tip[:3, 0])  # noqa: E731
    assert width(0.0) == pytest.approx(0.8 * width(0.06))
    assert peg.info["ends"] == 1 and "end_1" not in peg.frames


def test_same_seed_same_pair_and_bad_clearance_is_rejected():
    a, b = make_peg_hole_pair(4), make_peg_hole_pair(4)
    assert a[1].visual_mesh.vertices.tobytes() == b[1].visual_mesh.vertices.tobytes()
    assert a[0].visual_mesh.vertices.tobytes() == b[0].visual_mesh.vertices.tobytes()
    with pytest.raises(ValueError, match="clearance must be positive"):
        make_hole_module(sample_profile(np.random.default_rng(0)), np.random.default_rng(0), clearance=0.0)


def test_dataset_profile_pair_matches_the_reference():
    socket = load_dataset_object("profile_socket")
    assert socket.info["depth"] == pytest.approx(0.020) and socket.info["clearance"] == pytest.approx(0.001)
    np.testing.assert_allclose(socket.visual_mesh.bounds[1, :2] - socket.visual_mesh.bounds[0, :2], [0.05, 0.05])
    for name, length in [("profile_peg_short", 0.1), ("profile_peg_long", 0.2)]:
        peg = load_dataset_object(name)
        np.testing.assert_allclose(peg.visual_mesh.extents, [0.02, 0.02, length], atol=1e-9)
        assert peg.info["symmetry_order"] == 4 and set(peg.frames) == {"end_0", "end_1"}
        for end in ("end_0", "end_1"):
            assert _overlap(_peg_at_frame(peg, socket, end), socket.collision_parts) < 1e-12


def _peg_at_frame(peg, hole, end):
    mesh = peg.collision_parts[0].mesh.copy()
    mesh.apply_transform(hole.frames["bottom"] @ np.linalg.inv(peg.frames[end]))
    return mesh
