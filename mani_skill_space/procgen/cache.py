"""On-disk cache of generated arrays, keyed by content hash.

Several worker processes (e.g. ``AsyncVectorEnv``) may build the same entry at once: each writes a private
temporary file and atomically renames it into place, so a reader sees either nothing or a whole entry. Every
entry stores a checksum of its arrays; an entry that fails to load or verify is rebuilt, not trusted. Entries are
readable by everyone (mode 0644), so a cache can be shared by a group. A cache that cannot be written (a read-only
or uncreatable directory) costs time, not results: the rebuilt arrays are returned uncached, with a warning (once
per directory).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import warnings
import zipfile
from pathlib import Path
from typing import Callable

import numpy as np

CHECKSUM_KEY = "__sha256__"
ENTRY_MODE = 0o644
"""Entries are written by their owner and readable by everyone (tempfile would make them private, 0600)."""

_UNWRITABLE_DIRECTORIES: set[Path] = set()
"""Cache directories already warned about (one warning per directory and process)."""


def default_cache_dir() -> Path:
    root = os.environ.get("MANI_SKILL_SPACE_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "mani_skill_space")
    return Path(root)


def content_key(*parts: bytes | str) -> str:
    digest = hashlib.sha256()
    for part in parts:
        digest.update(part.encode() if isinstance(part, str) else part)
        digest.update(b"\0")
    return digest.hexdigest()


def arrays_checksum(arrays: dict[str, np.ndarray]) -> str:
    digest = hashlib.sha256()
    for name in sorted(arrays):
        array = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}:{array.dtype.str}:{array.shape}".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


class ArrayCache:
    """``get_or_create(key, build)`` returns the cached dict of arrays for ``key``, building it on a miss."""

    def __init__(self, namespace: str, root: Path | None = None):
        self.directory = Path(root or default_cache_dir()) / namespace

    def path(self, key: str) -> Path:
        return self.directory / f"{key}.npz"

    def get_or_create(self, key: str, build: Callable[[], dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        cached = self.load(key)
        if cached is not None:
            return cached
        arrays = {name: np.asarray(value) for name, value in build().items()}
        try:
            self.store(key, arrays)
        except OSError as error:
            if self.directory not in _UNWRITABLE_DIRECTORIES:
                _UNWRITABLE_DIRECTORIES.add(self.directory)
                warnings.warn(f"cannot write the asset cache {self.directory} ({error}); using uncached results (set MANI_SKILL_SPACE_CACHE to a writable folder)", stacklevel=2)
        return arrays

    def load(self, key: str) -> dict[str, np.ndarray] | None:
        """The entry's arrays, or None when it is missing, truncated or fails its checksum."""
        path = self.path(key)
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {name: data[name] for name in data.files if name != CHECKSUM_KEY}
                stored = str(data[CHECKSUM_KEY])
        except FileNotFoundError:
            return None
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
            return None
        return arrays if stored == arrays_checksum(arrays) else None

    def store(self, key: str, arrays: dict[str, np.ndarray]) -> None:
        self.directory.mkdir(parents=True, exist_ok=True)
        payload = dict(arrays)
        payload[CHECKSUM_KEY] = np.array(arrays_checksum(arrays))
        handle, temporary = tempfile.mkstemp(dir=self.directory, prefix=f".{key}.", suffix=".tmp")
        try:
            os.fchmod(handle, ENTRY_MODE)
            with os.fdopen(handle, "wb") as stream:
                np.savez(stream, **payload)
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(temporary, self.path(key))
        except BaseException:
            if os.path.exists(temporary):
                os.unlink(temporary)
            raise
