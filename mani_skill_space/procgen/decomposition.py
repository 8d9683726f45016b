"""Convex decomposition of arbitrary meshes with CoACD, cached on disk by content hash.

Procedural shapes build their convex parts constructively; this is only for meshes with no such structure
(e.g. a user's own dataset object). CoACD takes seconds per mesh, hence the cache.
"""

from __future__ import annotations

import json

import numpy as np
import trimesh

from mani_skill_space.procgen.asset import GPU_CONVEX_VERTEX_LIMIT
from mani_skill_space.procgen.cache import ArrayCache, content_key

DEFAULT_COACD_PARAMS = {"threshold": 0.05, "decimate": True, "max_ch_vertex": GPU_CONVEX_VERTEX_LIMIT, "seed": 0}


def convex_decomposition(mesh: trimesh.Trimesh, cache: ArrayCache | None = None, **coacd_params) -> list[trimesh.Trimesh]:
    """Convex parts approximating ``mesh`` (CoACD), each with at most 64 vertices, cached by mesh and parameters."""
    params = {**DEFAULT_COACD_PARAMS, **coacd_params}
    vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    key = content_key(vertices.tobytes(), faces.tobytes(), json.dumps(params, sort_keys=True))
    cache = cache or ArrayCache("coacd")
    arrays = cache.get_or_create(key, lambda: _run_coacd(vertices, faces, params))
    return _split_parts(arrays)


def _run_coacd(vertices: np.ndarray, faces: np.ndarray, params: dict) -> dict[str, np.ndarray]:
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(vertices, faces), **params)
    counts = np.array([len(v) for v, _ in parts], dtype=np.int64)
    return {"vertices": np.concatenate([v for v, _ in parts]).astype(np.float64), "counts": counts}


def _split_parts(arrays: dict[str, np.ndarray]) -> list[trimesh.Trimesh]:
    offsets = np.concatenate([[0], np.cumsum(arrays["counts"])])
    return [trimesh.convex.convex_hull(arrays["vertices"][a:b]) for a, b in zip(offsets[:-1], offsets[1:])]
