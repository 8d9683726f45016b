"""Convex polytopes as vertex sets, clipped by planes; and the exact convex decomposition of a convex solid
minus a convex cavity.

``solid \\ cavity`` for convex sets splits into convex pieces along the cavity's face planes: with the cavity
``{x : n_i . x <= c_i for all i}``, piece i is ``solid ∩ {n_j . x <= c_j, j < i} ∩ {n_i . x >= c_i}``. The
pieces are disjoint, each is convex, and together they are exactly the solid outside the cavity, so a hole
module's collision geometry needs no approximate decomposition (and no CoACD).
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import ConvexHull, QhullError

TOLERANCE = 1e-9
MIN_PIECE_VOLUME = 1e-10
"""Pieces smaller than this (m^3, a 0.5 mm cube) are slivers of floating-point noise and are dropped."""


def clip(vertices: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Vertices of the convex polytope ``hull(vertices) ∩ {x : normal . x <= offset}`` (empty when none; in any
    dimension: a polygon's vertices (k, 2) give a polygon)."""
    if len(vertices) == 0:
        return vertices
    side = vertices @ normal - offset
    inside, outside = side <= TOLERANCE, side > TOLERANCE
    if not outside.any():
        return vertices
    if not inside.any():
        return np.empty((0, vertices.shape[1]))
    a, b = vertices[inside], vertices[outside]
    sa, sb = side[inside][:, None], side[outside][None, :]
    # every segment from a kept to a dropped vertex crosses the plane; the crossings include those of the edges
    t = (sa / (sa - sb))[..., None]
    crossings = (a[:, None, :] + t * (b[None, :, :] - a[:, None, :])).reshape(-1, vertices.shape[1])
    return hull_vertices(np.concatenate([a, crossings]))


def hull_vertices(points: np.ndarray) -> np.ndarray:
    """The extreme points of ``points`` (empty if they span no volume)."""
    try:
        return points[ConvexHull(points).vertices]
    except (QhullError, ValueError):
        return np.empty((0, points.shape[1]))


def face_planes(vertices: np.ndarray) -> list[tuple[np.ndarray, float]]:
    """Outward unit normal n and offset c of each face plane of ``hull(vertices)``: the hull is n . x <= c."""
    hull = ConvexHull(vertices)
    planes = np.unique(np.round(hull.equations, 9), axis=0)
    return [(plane[:3] / np.linalg.norm(plane[:3]), -plane[3] / np.linalg.norm(plane[:3])) for plane in planes]


def subtract_convex(solid: np.ndarray, cavity: np.ndarray) -> list[np.ndarray]:
    """Convex pieces (vertex sets) exactly covering ``hull(solid)`` outside ``hull(cavity)``."""
    return [piece for piece, _ in _pieces_with_hulls(solid, cavity)]


def subtract_convex_meshes(solid: np.ndarray, cavity: np.ndarray) -> list[trimesh.Trimesh]:
    """``subtract_convex``'s pieces as meshes (``convex_mesh`` of each), each hull computed once."""
    return [_mesh_of_hull(hull) for _, hull in _pieces_with_hulls(solid, cavity)]


def _pieces_with_hulls(solid: np.ndarray, cavity: np.ndarray) -> list[tuple[np.ndarray, ConvexHull]]:
    pieces, remaining = [], solid
    for normal, offset in face_planes(cavity):
        piece = clip(remaining, -normal, -offset)  # the part beyond this face of the cavity
        hull = _hull_or_none(piece)
        if hull is not None and hull.volume > MIN_PIECE_VOLUME:
            pieces.append((piece, hull))
        remaining = clip(remaining, normal, offset)
        if len(remaining) == 0:
            break
    return pieces


def _hull_or_none(vertices: np.ndarray) -> ConvexHull | None:
    if len(vertices) < 4:
        return None
    try:
        return ConvexHull(vertices)
    except (QhullError, ValueError):
        return None


def convex_mesh(vertices: np.ndarray) -> trimesh.Trimesh:
    """The hull of ``vertices`` as a closed, outward-wound mesh (faster than trimesh's general hull repair)."""
    return _mesh_of_hull(ConvexHull(vertices))


def _mesh_of_hull(hull: ConvexHull) -> trimesh.Trimesh:
    faces = hull.simplices.copy()
    a, b, c = (hull.points[faces[:, i]] for i in range(3))
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), hull.equations[:, :3]) < 0
    faces[inward] = faces[inward][:, ::-1]
    used, faces = np.unique(faces, return_inverse=True)
    return trimesh.Trimesh(hull.points[used], faces.reshape(-1, 3), process=False)
