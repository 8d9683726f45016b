"""Make the README's pictures (JPEG, a few hundred KB in all) next to this file.

    python assets/readme/make_pictures.py

- ``showcase.jpg``: every task in each of its domains and asset sources, one row per task, one tile per domain
  and asset source: the render camera's first frame after reset (seed 0), as in the picture grid of
  ``python -m mani_skill_space.showcase``.
- ``procedural_variety.jpg``: 16 rocks, 16 peg and hole pairs, 16 debris pieces and 4 solar panel sets
  (``mani_skill_space.showcase.procedural_variety``).

This folder is not part of the package (setup.cfg's package data leaves it out).
"""

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

import mani_skill_space
from mani_skill_space.envs import task_class
from mani_skill_space.showcase import Args, procedural_variety, rollout_frames

HERE = Path(__file__).resolve().parent
TILE = 160
"""Pixels per side of a showcase tile (rendered at twice the size, then downscaled)."""
JPEG_QUALITY = 85


def showcase_grid() -> np.ndarray:
    """One row per task, one tile per (domain, asset source); rows shorter than the longest are padded black."""
    args = Args(steps=0, image_size=2 * TILE)
    rows = []
    for env_id in mani_skill_space.ENV_IDS:
        task = task_class(env_id)
        tiles = []
        for domain in task.SUPPORTED_DOMAINS:
            for source in task.SUPPORTED_ASSET_SOURCES:
                (frame,) = rollout_frames(env_id, domain, source, args)
                tile = Image.fromarray(frame).resize((TILE, TILE), Image.Resampling.LANCZOS)
                tiles.append(_caption(tile, [env_id, f"{domain}, {source}"]))
                print(f"{env_id} {domain} {source}")
        rows.append(np.concatenate(tiles, axis=1))
    width = max(row.shape[1] for row in rows)
    return np.concatenate([np.pad(row, ((0, 0), (0, width - row.shape[1]), (0, 0))) for row in rows], axis=0)


def _caption(tile: Image.Image, lines: list[str]) -> np.ndarray:
    draw = ImageDraw.Draw(tile)
    draw.rectangle([0, 0, 8 + 6 * max(map(len, lines)), 4 + 12 * len(lines)], fill=(0, 0, 0))
    for i, line in enumerate(lines):
        draw.text((4, 2 + 12 * i), line, fill=(255, 255, 255))
    return np.asarray(tile)


def main() -> None:
    for name, picture in (("procedural_variety.jpg", procedural_variety()), ("showcase.jpg", showcase_grid())):
        path = HERE / name
        Image.fromarray(picture).save(path, quality=JPEG_QUALITY, optimize=True)
        print(f"{path}: {picture.shape[1]} x {picture.shape[0]} px, {path.stat().st_size // 1024} KB")


if __name__ == "__main__":
    main()
