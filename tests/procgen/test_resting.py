import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull, Delaunay
from scipy.spatial.transform import Rotation

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.procgen.resting import _distance_inside_polygon, resting_orientations
from mani_skill_space.procgen.rock import make_rock


def _rotated(vertices, quaternion):
    return vertices @ Rotation.from_quat(np.roll(quaternion, -1)).as_matrix().T


@pytest.mark.parametrize("seed", range(10))
def test_each_resting_orientation_puts_a_face_down_under_the_centre_of_mass(seed):
    vertices = make_rock(seed).collision_vertices
    orientations = resting_orientations(vertices)
    assert len(orientations) >= 1
    for quaternion in orientations:
        turned = _rotated(vertices, quaternion)
        bottom = turned[:, 2].min()
        face = turned[turned[:, 2] < bottom + 1e-7]
        assert len(face) >= 3  # a face, not an edge or a vertex, touches the ground
        assert Delaunay(face[:, :2]).find_simplex([0.0, 0.0]) >= 0  # the centre of mass is over the face


def test_a_cube_rests_on_its_six_faces_and_a_tube_lies_on_its_sides():
    cube = trimesh.creation.box(extents=[0.05, 0.05, 0.05]).vertices
    assert len(resting_orientations(cube)) == 6
    tube = load_dataset_object("sample_tube")
    lying = resting_orientations(tube.collision_vertices, exclude_axis=np.array([1.0, 0.0, 0.0]))
    assert len(lying) == 24  # the prism's side faces, never its end caps
    for quaternion in lying:
        axis = _rotated(np.array([[1.0, 0.0, 0.0]]), quaternion)[0]
        assert abs(axis[2]) < 1e-6


def test_a_body_whose_centre_of_mass_is_outside_has_no_stable_face():
    with pytest.raises(ValueError, match="no statically stable face"):
        resting_orientations(trimesh.creation.box(extents=[0.05, 0.05, 0.05]).vertices, centre_of_mass=(0.0, 1.0, 1.0))


def test_without_a_face_that_stable_the_most_stable_face_is_used():
    cube = trimesh.creation.box(extents=[0.05, 0.05, 0.05]).vertices
    near_a_corner = (0.024, 0.024, 0.024)  # every face's margin is 1 mm, below the 2 mm asked for
    assert len(resting_orientations(cube, centre_of_mass=near_a_corner)) == 1
    assert len(resting_orientations(cube, centre_of_mass=near_a_corner, margin=0.0005)) == 6


@pytest.mark.parametrize("seed", range(20))
def test_the_distance_inside_a_face_is_the_least_over_its_edges_in_any_vertex_order(seed):
    """A face's corners come in no particular order; the polygon they make is walked counter-clockwise, as a 2-D hull
    of them would, and the point's distance to it is the nearest edge's (negative outside)."""
    rng = np.random.default_rng(seed)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    u = np.cross(normal, rng.normal(size=3))
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    flat = rng.normal(size=(12, 2)) * rng.uniform(0.01, 0.05, 2)
    corners = flat[ConvexHull(flat).vertices]  # counter-clockwise
    point_flat = rng.normal(size=2) * 0.02
    edges = np.roll(corners, -1, axis=0) - corners
    expected = np.min((edges[:, 0] * (corners[:, 1] - point_flat[1]) * -1 + edges[:, 1] * (corners[:, 0] - point_flat[0])) / np.linalg.norm(edges, axis=1))
    offset = rng.normal(size=3)
    polygon = offset + corners[rng.permutation(len(corners))] @ np.stack([u, v])
    point = offset + point_flat @ np.stack([u, v])
    assert _distance_inside_polygon(point, polygon, normal) == pytest.approx(expected, abs=1e-12)
