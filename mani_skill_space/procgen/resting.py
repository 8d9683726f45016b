"""Statically stable resting orientations of a rigid body on flat ground.

A convex body (or the convex hull of any body) rests stably on a face of its hull when its centre of mass
projects inside that face. Placing samples that way means they start at rest instead of toppling over during
the first steps of an episode, which matters most in low gravity where settling takes seconds.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
from scipy.spatial import ConvexHull

DOWN = np.array([0.0, 0.0, -1.0])


def resting_orientations(
    vertices: np.ndarray, centre_of_mass=(0.0, 0.0, 0.0), margin: float = 0.002, exclude_axis: Optional[np.ndarray] = None
) -> np.ndarray:
    """wxyz quaternions, one per stable hull face, that turn the body so that face points straight down.

    A face is stable when the centre of mass projects inside it at least ``margin`` (m) from its edges; if no
    face is that stable, the single most stable one is returned. Faces whose normal is within 10 degrees of
    ``exclude_axis`` (either way) are skipped, e.g. to keep a tube from standing on its end.
    """
    hull = ConvexHull(np.asarray(vertices, dtype=np.float64))
    com = np.asarray(centre_of_mass, dtype=np.float64)
    normals, margins = [], []
    for normal, face_points in _faces(hull):
        if exclude_axis is not None and abs(normal @ exclude_axis) > np.cos(np.radians(10)):
            continue
        projection = com - ((com - face_points[0]) @ normal) * normal
        normals.append(normal)
        margins.append(_distance_inside_polygon(projection, face_points, normal))
    margins = np.asarray(margins)
    if not len(margins) or margins.max() <= 0:
        raise ValueError("the body has no statically stable face (is the centre of mass inside it?)")
    chosen = np.flatnonzero(margins >= margin) if margins.max() >= margin else [int(np.argmax(margins))]
    return np.stack([_quaternion_between(normals[i], DOWN) for i in chosen])


def _faces(hull: ConvexHull):
    """Outward unit normal and the points of each planar hull face (coplanar triangles merged)."""
    keys = np.round(hull.equations, 6)
    _, group_of = np.unique(keys, axis=0, return_inverse=True)
    for group in np.unique(group_of):
        simplices = hull.simplices[group_of.ravel() == group]
        normal = hull.equations[group_of.ravel() == group][0, :3]
        yield normal / np.linalg.norm(normal), hull.points[np.unique(simplices)]


def _distance_inside_polygon(point: np.ndarray, polygon: np.ndarray, normal: np.ndarray) -> float:
    """Least distance from ``point`` to the edges of a planar convex polygon; negative when outside."""
    u = _cross(normal, np.array([1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0]))
    u /= np.linalg.norm(u)
    v = _cross(normal, u)
    flat = np.stack([(polygon - point) @ u, (polygon - point) @ v], axis=1)  # the point is the origin here
    # the face's vertices are its polygon's corners: ordered by angle about their mean, they go counter-clockwise
    # (a 2-D hull per face would give the same order; its set-up made it most of this function's time)
    centred = flat - flat.mean(axis=0)
    outline = flat[np.argsort(np.arctan2(centred[:, 1], centred[:, 0]))]
    edges = np.roll(outline, -1, axis=0) - outline
    # signed distance of the origin to each edge's line, positive inside a counter-clockwise polygon
    distances = (edges[:, 0] * -outline[:, 1] - edges[:, 1] * -outline[:, 0]) / np.linalg.norm(edges, axis=1)
    return float(distances.min())


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of two 3-vectors, the same arithmetic without its array set-up (it is called once per face)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _quaternion_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest-arc wxyz quaternion rotating unit vector ``a`` onto unit vector ``b``."""
    cross = np.cross(a, b)
    dot = float(a @ b)
    if dot < -1 + 1e-9:  # opposite: turn half a circle about any axis perpendicular to a
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        return np.array([0.0, *(axis / np.linalg.norm(axis))])
    quaternion = np.array([1.0 + dot, *cross])
    return quaternion / np.linalg.norm(quaternion)
