import numpy as np

from mani_skill_space.procgen.skydome import make_skydome_mesh


def test_skydome_faces_and_normals_point_inwards():
    vertices, triangles, normals, uvs = make_skydome_mesh(10.0, rings=8, segments=16)
    a, b, c = (vertices[triangles[:, i]].astype(np.float64) for i in range(3))
    face_normals = np.cross(b - a, c - a)
    centres = (a + b + c) / 3
    valid = np.linalg.norm(face_normals, axis=1) > 1e-9  # skip the degenerate triangles at the poles
    assert np.all(np.einsum("ij,ij->i", face_normals[valid], centres[valid]) < 0)
    np.testing.assert_allclose(np.einsum("ij,ij->i", normals, vertices) / 10.0, -1.0, atol=1e-5)


def test_skydome_uv_matches_the_equirectangular_convention():
    vertices, _, _, uvs = make_skydome_mesh(5.0)
    zenith = uvs[:, 1] == 0
    assert np.allclose(vertices[zenith, 2], 5.0)
    horizon = np.isclose(uvs[:, 1], 0.5)
    assert np.allclose(vertices[horizon, 2], 0.0, atol=1e-5)
    assert uvs.min() == 0.0 and uvs.max() == 1.0
