import numpy as np
import pytest

from mani_skill_space.domains import DOMAINS
from mani_skill_space.procgen.terrain import FLAT_RADIUS, TERRAIN_HALF_EXTENT, make_terrain

STYLES = [name for name, d in DOMAINS.items() if d.terrain is not None]


@pytest.mark.parametrize("domain", STYLES)
def test_terrain_is_exactly_flat_around_the_robot_and_rough_elsewhere(domain):
    mesh = make_terrain(1, DOMAINS[domain].terrain).visual_mesh
    radius = np.hypot(mesh.vertices[:, 0], mesh.vertices[:, 1])
    assert np.all(mesh.vertices[radius <= FLAT_RADIUS, 2] == 0.0)
    outside = mesh.vertices[radius > FLAT_RADIUS + 1.0, 2]
    assert outside.std() > 0.01
    assert np.abs(mesh.vertices[:, 2]).max() < 1.0


@pytest.mark.parametrize("domain", STYLES)
def test_terrain_covers_its_square_and_collides_with_its_own_mesh(domain):
    terrain = make_terrain(2, DOMAINS[domain].terrain)
    mesh = terrain.visual_mesh
    np.testing.assert_allclose(mesh.bounds[:, :2], [[-TERRAIN_HALF_EXTENT] * 2, [TERRAIN_HALF_EXTENT] * 2])
    (collision,) = terrain.collision_parts
    assert not collision.convex
    assert collision.mesh is mesh
    assert np.all(mesh.face_normals[:, 2] > 0)  # faces point up: the ground's top side
    assert terrain.visual_parts[0].texture == DOMAINS[domain].terrain.texture
    assert terrain.visual_parts[0].uv.shape == (len(mesh.vertices), 2)


def test_terrain_is_deterministic_per_seed():
    style = DOMAINS["moon"].terrain
    a, b, c = (make_terrain(s, style).visual_mesh.vertices for s in (5, 5, 6))
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)
