"""Regenerate every static asset of mani-skill-space: sky and ground textures and the dataset objects.

    python -m mani_skill_space.assets.make_assets        # writes into this folder

All outputs are deterministic functions of the code here, so the shipped files can be checked against it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart, cylinder_mesh
from mani_skill_space.procgen.asset_io import save_asset
from mani_skill_space.procgen.textures import GROUND_KINDS, SKY_KINDS, make_ground_texture, make_sky_texture

ASSET_ROOT = Path(__file__).resolve().parent
SKY_SIZE = (1024, 512)
GROUND_TEXTURE_SIZE = 256

SAMPLE_TUBE_DIAMETER = 0.033
SAMPLE_TUBE_LENGTH = 0.170
SAMPLE_TUBE_CAP_LENGTH = 0.025
SAMPLE_TUBE_DENSITY = 1500.0
SAMPLE_TUBE_SECTIONS = 24


def make_sample_tube() -> Asset:
    """The Mars-2020-style sample tube of the reference: a 33 mm x 170 mm cylinder with a coloured cap.

    Axis along x, centred on its centre of mass. Body and cap share the radius, so the whole tube is one
    convex prism and its collision part is exact.
    """
    radius = SAMPLE_TUBE_DIAMETER / 2
    body_length = SAMPLE_TUBE_LENGTH - SAMPLE_TUBE_CAP_LENGTH
    half = SAMPLE_TUBE_LENGTH / 2
    body = cylinder_mesh(radius, body_length, SAMPLE_TUBE_SECTIONS, (-half + body_length / 2, 0, 0), axis="x")
    cap = cylinder_mesh(radius, SAMPLE_TUBE_CAP_LENGTH, SAMPLE_TUBE_SECTIONS, (half - SAMPLE_TUBE_CAP_LENGTH / 2, 0, 0), axis="x")
    whole = cylinder_mesh(radius, SAMPLE_TUBE_LENGTH, SAMPLE_TUBE_SECTIONS, axis="x")
    return Asset(
        name="sample_tube",
        visual_parts=(
            VisualPart(body, (0.78, 0.78, 0.8, 1.0), roughness=0.3, metallic=0.9, flat_shading=False),
            VisualPart(cap, (0.15, 0.35, 0.75, 1.0), roughness=0.5, metallic=0.2, flat_shading=False),
        ),
        collision_parts=(CollisionPart(whole),),
        density=SAMPLE_TUBE_DENSITY,
        info={"extents": [SAMPLE_TUBE_LENGTH, SAMPLE_TUBE_DIAMETER, SAMPLE_TUBE_DIAMETER], "axis": [1.0, 0.0, 0.0]},
    )


DATASET_OBJECTS = {"sample_tube": make_sample_tube}


def write_textures(root: Path = ASSET_ROOT) -> list[Path]:
    written = []
    for kind in SKY_KINDS:
        written.append(_write_png(make_sky_texture(kind, *SKY_SIZE), root / "sky" / f"{kind}.png"))
    for kind in GROUND_KINDS:
        written.append(_write_png(make_ground_texture(kind, GROUND_TEXTURE_SIZE), root / "textures" / f"{kind}.png"))
    return written


def write_dataset(root: Path = ASSET_ROOT) -> list[Path]:
    return [save_asset(make(), root / "dataset" / name) for name, make in DATASET_OBJECTS.items()]


def _write_png(image: np.ndarray, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(image).save(path, optimize=True)
    return path


def main() -> None:
    for path in write_textures() + write_dataset():
        print(path)


if __name__ == "__main__":
    main()
