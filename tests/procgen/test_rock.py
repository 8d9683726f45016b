import manifold3d
import numpy as np
import pytest
import trimesh

from mani_skill_space.procgen.asset import GPU_CONVEX_VERTEX_LIMIT
from mani_skill_space.procgen.rock import DEFAULT_ROCK_SIZE, ROCK_FLAVOURS, make_rock

SEEDS = range(25)


def _manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    return manifold3d.Manifold(manifold3d.Mesh(vert_properties=np.asarray(mesh.vertices, np.float32), tri_verts=np.asarray(mesh.faces, np.uint32)))


def _union_of_parts(rock) -> manifold3d.Manifold:
    return manifold3d.Manifold.batch_boolean([_manifold(p.mesh) for p in rock.collision_parts], manifold3d.OpType.Add)


@pytest.mark.parametrize("flavour", list(ROCK_FLAVOURS))
def test_rock_size_is_about_six_by_six_by_four_centimetres(flavour):
    for seed in SEEDS:
        extents = make_rock(seed, flavour).visual_mesh.extents
        assert np.all(extents > 0.6 * np.array(DEFAULT_ROCK_SIZE)), extents
        assert np.all(extents < 1.4 * np.array(DEFAULT_ROCK_SIZE)), extents


@pytest.mark.parametrize("flavour", list(ROCK_FLAVOURS))
def test_rock_visual_is_a_watertight_solid_centred_on_its_centre_of_mass(flavour):
    for seed in SEEDS:
        mesh = make_rock(seed, flavour).visual_mesh
        assert mesh.is_watertight and mesh.is_volume
        np.testing.assert_allclose(mesh.center_mass, 0.0, atol=1e-9)


@pytest.mark.parametrize("flavour", list(ROCK_FLAVOURS))
def test_convex_parts_cover_exactly_the_visual_volume(flavour):
    for seed in SEEDS:
        rock = make_rock(seed, flavour)
        visual = _manifold(rock.visual_mesh)
        parts = _union_of_parts(rock)
        volume = visual.volume()
        assert abs(parts.volume() - volume) / volume < 0.02
        assert (visual ^ parts).volume() / volume > 0.98  # ^ is intersection in manifold3d


@pytest.mark.parametrize("flavour", list(ROCK_FLAVOURS))
def test_rock_collision_parts_are_convex_and_gpu_cookable(flavour):
    for seed in SEEDS:
        for part in make_rock(seed, flavour).collision_parts:
            assert part.convex and part.mesh.is_convex
            assert len(part.mesh.vertices) <= GPU_CONVEX_VERTEX_LIMIT


def test_same_seed_gives_the_same_bytes_and_different_seeds_differ():
    a, b, c = make_rock(7), make_rock(7), make_rock(8)
    assert a.visual_mesh.vertices.tobytes() == b.visual_mesh.vertices.tobytes()
    assert a.visual_mesh.faces.tobytes() == b.visual_mesh.faces.tobytes()
    assert [p.mesh.vertices.tobytes() for p in a.collision_parts] == [p.mesh.vertices.tobytes() for p in b.collision_parts]
    assert a.visual_mesh.vertices.shape != c.visual_mesh.vertices.shape or not np.allclose(a.visual_mesh.vertices, c.visual_mesh.vertices)


def test_lunar_and_martian_rocks_differ_in_shape_and_colour():
    lunar = [make_rock(s, "lunar") for s in SEEDS]
    martian = [make_rock(s, "martian") for s in SEEDS]
    mean_vertices = lambda rocks: np.mean([len(p.mesh.vertices) for r in rocks for p in r.collision_parts])  # noqa: E731
    assert mean_vertices(martian) > 1.5 * mean_vertices(lunar)  # rounder: many more facets
    redness = lambda rocks: np.mean([r.visual_parts[0].color[0] - r.visual_parts[0].color[2] for r in rocks])  # noqa: E731
    assert redness(martian) > redness(lunar) + 0.1


def test_unknown_flavour_names_the_valid_choices():
    with pytest.raises(ValueError, match="lunar.*martian"):
        make_rock(0, "venusian")


def test_rock_mass_follows_its_density():
    rock = make_rock(3)
    mass, com, inertia = rock.mass_properties()
    assert mass == pytest.approx(2000.0 * rock.visual_mesh.volume)
    assert 0.05 < mass < 0.4
    assert np.all(np.linalg.eigvalsh(inertia) > 0)
