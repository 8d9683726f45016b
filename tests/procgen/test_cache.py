import multiprocessing as mp
import stat
import tempfile

import numpy as np
import pytest
import trimesh

from mani_skill_space.procgen.cache import ArrayCache
from mani_skill_space.procgen.decomposition import convex_decomposition


def _build_arrays():
    return {"vertices": np.arange(30_000, dtype=np.float64).reshape(-1, 3), "counts": np.array([10_000])}


def _write_same_entry(root, key, barrier, results):
    barrier.wait()  # both processes build and write the entry at the same moment
    arrays = ArrayCache("race", root).get_or_create(key, _build_arrays)
    results.put(float(arrays["vertices"].sum()))


def test_two_processes_writing_the_same_entry_both_get_a_valid_entry(tmp_path):
    context = mp.get_context("spawn")
    barrier, results = context.Barrier(2), context.Queue()
    workers = [context.Process(target=_write_same_entry, args=(tmp_path, "same-key", barrier, results)) for _ in range(2)]
    for w in workers:
        w.start()
    for w in workers:
        w.join(timeout=60)
        assert w.exitcode == 0
    expected = float(_build_arrays()["vertices"].sum())
    assert [results.get(timeout=5), results.get(timeout=5)] == [expected, expected]
    cache = ArrayCache("race", tmp_path)
    assert cache.load("same-key") is not None
    assert not list(cache.directory.glob("*.tmp")), "temporary files were left behind"


def test_corrupted_entry_is_rebuilt_not_trusted(tmp_path):
    cache = ArrayCache("corrupt", tmp_path)
    cache.get_or_create("k", _build_arrays)
    data = cache.path("k").read_bytes()
    cache.path("k").write_bytes(data[: len(data) // 2])  # truncated, as after a crash mid-write
    calls = []
    arrays = cache.get_or_create("k", lambda: calls.append(1) or _build_arrays())
    assert calls == [1]
    np.testing.assert_array_equal(arrays["vertices"], _build_arrays()["vertices"])
    assert cache.load("k") is not None


def test_entry_with_a_wrong_checksum_is_rebuilt(tmp_path):
    cache = ArrayCache("checksum", tmp_path)
    cache.get_or_create("k", _build_arrays)
    with np.load(cache.path("k")) as data:
        payload = {name: data[name] for name in data.files}
    payload["vertices"] = payload["vertices"] + 1.0  # bit rot: the arrays no longer match their checksum
    np.savez(cache.path("k"), **payload)
    assert cache.load("k") is None


def test_cache_hit_does_not_rebuild(tmp_path):
    cache = ArrayCache("hit", tmp_path)
    calls = []
    for _ in range(3):
        cache.get_or_create("k", lambda: calls.append(1) or _build_arrays())
    assert calls == [1]


def _l_shape() -> trimesh.Trimesh:
    a = trimesh.creation.box(extents=[0.1, 0.02, 0.02])
    b = trimesh.creation.box(extents=[0.02, 0.08, 0.02])
    b.apply_translation([0.04, 0.03, 0])
    return trimesh.boolean.union([a, b], engine="manifold")


def test_coacd_decomposition_covers_a_nonconvex_mesh_and_is_cached(tmp_path):
    mesh = _l_shape()
    cache = ArrayCache("coacd", tmp_path)
    parts = convex_decomposition(mesh, cache=cache)
    assert len(parts) >= 2
    assert all(p.is_convex and len(p.vertices) <= 64 for p in parts)
    assert abs(sum(p.volume for p in parts) - mesh.volume) / mesh.volume < 0.15
    assert len(list(cache.directory.glob("*.npz"))) == 1
    again = convex_decomposition(mesh, cache=cache)
    assert [p.vertices.tobytes() for p in again] == [p.vertices.tobytes() for p in parts]


def test_entries_are_readable_by_a_shared_group(tmp_path):
    cache = ArrayCache("modes", tmp_path)
    cache.get_or_create("k", _build_arrays)
    assert stat.S_IMODE(cache.path("k").stat().st_mode) == 0o644


def test_an_uncreatable_cache_directory_gives_the_built_arrays_with_one_warning(tmp_path):
    blocker = tmp_path / "not_a_directory"
    blocker.write_text("a file where the cache directory should be")
    cache = ArrayCache("uncreatable", blocker)
    with pytest.warns(UserWarning, match="cannot write the asset cache") as warned:
        first = cache.get_or_create("a", _build_arrays)
        second = cache.get_or_create("b", _build_arrays)
    assert len(warned) == 1, "one warning per directory"
    for arrays in (first, second):
        np.testing.assert_array_equal(arrays["vertices"], _build_arrays()["vertices"])


def test_a_read_only_cache_with_a_corrupt_entry_gives_the_built_arrays(tmp_path, monkeypatch):
    cache = ArrayCache("read_only", tmp_path)
    cache.get_or_create("k", _build_arrays)
    cache.path("k").write_bytes(b"corrupt")

    def read_only_directory(*args, **kwargs):  # what mkstemp meets in a directory without write permission
        raise PermissionError(13, "Permission denied", str(cache.directory))

    monkeypatch.setattr(tempfile, "mkstemp", read_only_directory)
    with pytest.warns(UserWarning, match=r"cannot write the asset cache .*Permission denied"):
        arrays = cache.get_or_create("k", _build_arrays)
    np.testing.assert_array_equal(arrays["vertices"], _build_arrays()["vertices"])
    assert cache.path("k").read_bytes() == b"corrupt", "nothing was written"
