"""Skydome geometry: an inward-facing UV sphere for equirectangular sky textures (see ``textures``)."""

from __future__ import annotations

import numpy as np


def make_skydome_mesh(radius: float, rings: int = 32, segments: int = 64):
    """Vertices, triangles (wound to face the centre), inward normals and UVs of a latitude-longitude sphere.

    UV convention matches ``textures.make_sky_texture``: u = azimuth / 2pi, v = polar angle / pi (v = 0 at
    the zenith). The seam column is duplicated so that u runs continuously from 0 to 1.
    """
    polar = np.linspace(0.0, np.pi, rings + 1)
    azimuth = np.linspace(0.0, 2 * np.pi, segments + 1)
    theta, phi = np.meshgrid(polar, azimuth, indexing="ij")
    directions = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1).reshape(-1, 3)
    uvs = np.stack([phi / (2 * np.pi), theta / np.pi], axis=-1).reshape(-1, 2)

    idx = np.arange((rings + 1) * (segments + 1)).reshape(rings + 1, segments + 1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    # Outward-facing order would be (a, c, d), (a, d, b); reversed so the inside is the front face.
    triangles = np.concatenate([np.stack([a, d, c], axis=1), np.stack([a, b, d], axis=1)])
    return (
        (directions * radius).astype(np.float32),
        triangles.astype(np.uint32),
        (-directions).astype(np.float32),
        uvs.astype(np.float32),
    )
