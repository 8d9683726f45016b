"""Static ("dataset") objects and textures shipped inside the package."""

from __future__ import annotations

import functools
from importlib import resources
from pathlib import Path

from mani_skill_space.procgen.asset import Asset
from mani_skill_space.procgen.asset_io import MANIFEST, load_asset


def asset_root() -> Path:
    return Path(str(resources.files("mani_skill_space.assets")))


def dataset_object_names() -> tuple[str, ...]:
    root = asset_root() / "dataset"
    return tuple(sorted(p.parent.name for p in root.glob(f"*/{MANIFEST}")))


@functools.lru_cache(maxsize=None)
def load_dataset_object(name: str) -> Asset:
    valid = dataset_object_names()
    if name not in valid:
        raise ValueError(f"Unknown dataset object {name!r}; valid choices: {', '.join(valid)}")
    return load_asset(asset_root() / "dataset" / name)


def sky_texture_path(kind: str) -> Path:
    return _existing(asset_root() / "sky" / f"{kind}.png", "sky texture")


def ground_texture_path(kind: str) -> Path:
    return _existing(asset_root() / "textures" / f"{kind}.png", "ground texture")


def _existing(path: Path, what: str) -> Path:
    if not path.is_file():
        available = sorted(p.stem for p in path.parent.glob("*.png"))
        raise ValueError(f"Unknown {what} {path.stem!r}; valid choices: {', '.join(available)}")
    return path
