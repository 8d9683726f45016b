"""Regenerate every static asset of mani-skill-space: sky and ground textures and the dataset objects.

    python -m mani_skill_space.assets.make_assets        # writes into this folder

All outputs are deterministic functions of the code here, so the shipped files can be checked against it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart, box_mesh, cylinder_mesh, translation_frame
from mani_skill_space.procgen.asset_io import save_asset
from mani_skill_space.procgen.peg_hole import METAL_FRICTION
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


PROFILE_PEG_WIDTH = 0.020
PROFILE_PEG_LENGTHS = {"short": 0.100, "long": 0.200}
SOCKET_INNER = 0.022
SOCKET_OUTER = 0.026
SOCKET_DEPTH = 0.020
POST_WIDTH = 0.050
POST_HEIGHT = 0.080
"""The reference socket stands 40 mm proud of the ground; ours stands on a taller post so that the entrance
is at 0.1 m, close to the procedural module's 0.12 m top, keeping the two asset sources' workspaces alike."""
ALUMINIUM = (0.75, 0.76, 0.78, 1.0)
ANODISED = (0.3, 0.32, 0.36, 1.0)


def make_profile_peg(length: float) -> Asset:
    """The reference's 20 x 20 mm aluminium profile peg (a box; the reference also collides with its box).

    Axis along z, centred. Both ends fit the socket, so both are ``end_*`` frames; 4-fold symmetric."""
    half = np.array([PROFILE_PEG_WIDTH / 2, PROFILE_PEG_WIDTH / 2, length / 2])
    mesh = box_mesh(half)
    tip = translation_frame((0.0, 0.0, -length / 2))
    head = np.diag([1.0, -1.0, -1.0, 1.0])
    head[:3, 3] = (0.0, 0.0, length / 2)
    return Asset(
        name=f"profile_peg_{int(round(length * 1000))}mm",
        visual_parts=(VisualPart(mesh, ALUMINIUM, roughness=0.35, metallic=0.8),),
        collision_parts=(CollisionPart(mesh),),
        density=2700.0 * 0.45,  # a hollow extrusion: about 45% of the box is aluminium
        friction=METAL_FRICTION,
        frames={"end_0": tip, "end_1": head},
        info={"symmetry_order": 4, "ends": 2, "radius": PROFILE_PEG_WIDTH / 2, "height": length},
    )


def make_profile_socket() -> Asset:
    """The reference's socket: 22 x 22 mm inside (1 mm clearance per side), 26 x 26 mm outside, 20 mm deep, on a
    50 x 50 mm post. Origin at the post's base; every part is a box."""
    top = POST_HEIGHT + SOCKET_DEPTH
    wall = (SOCKET_OUTER - SOCKET_INNER) / 2
    boxes = [box_mesh((POST_WIDTH / 2, POST_WIDTH / 2, POST_HEIGHT / 2), (0, 0, POST_HEIGHT / 2))]
    centre_z = POST_HEIGHT + SOCKET_DEPTH / 2
    for side in (-1, 1):
        offset = (SOCKET_INNER + wall) / 2 * side
        boxes.append(box_mesh((wall / 2, SOCKET_OUTER / 2, SOCKET_DEPTH / 2), (offset, 0, centre_z)))
        boxes.append(box_mesh((SOCKET_INNER / 2, wall / 2, SOCKET_DEPTH / 2), (0, offset, centre_z)))
    return Asset(
        name="profile_socket",
        visual_parts=tuple(VisualPart(b, ANODISED, roughness=0.5, metallic=0.5) for b in boxes),
        collision_parts=tuple(CollisionPart(b) for b in boxes),
        friction=METAL_FRICTION,
        frames={"entrance": translation_frame((0, 0, top)), "bottom": translation_frame((0, 0, POST_HEIGHT))},
        info={"depth": SOCKET_DEPTH, "clearance": (SOCKET_INNER - PROFILE_PEG_WIDTH) / 2, "symmetry_order": 4},
    )


CUBESAT_SCALE = 0.4
"""The standard 10 cm CubeSat unit at 40%, 4 cm (ManiSkill's PickCube size): the Panda's fingers open to 8 cm,
so a full-size bus could not be grasped, and a tumbling cube must fit between them whichever way it turns
(a 4 cm cube's body diagonal is 6.9 cm; the reference scaled its model to 5 cm, 8.7 cm corner to corner)."""
CUBESAT_UNIT = 0.1 * CUBESAT_SCALE
CUBESAT_HEIGHTS = {"1u": 0.1135 * CUBESAT_SCALE, "3u": 0.3405 * CUBESAT_SCALE}
CUBESAT_RAIL = 0.0085 * CUBESAT_SCALE


def make_cubesat(units: str) -> Asset:
    """A 1U or 3U CubeSat at 40% scale: a body with solar cells between four corner rails, 1330 kg/m^3."""
    height = CUBESAT_HEIGHTS[units]
    half = CUBESAT_UNIT / 2
    rail = CUBESAT_RAIL
    body = box_mesh((half - 0.0008, half - 0.0008, height / 2 - 0.002))
    rails = [box_mesh((rail / 2, rail / 2, height / 2), (x * (half - rail / 2), y * (half - rail / 2), 0.0)) for x in (-1, 1) for y in (-1, 1)]
    solid = trimesh.boolean.union([body, *rails], engine="manifold")
    return Asset(
        name=f"cubesat_{units}",
        visual_parts=(VisualPart(body, (0.08, 0.12, 0.4, 1.0), roughness=0.3, metallic=0.4), *(VisualPart(r, ALUMINIUM, roughness=0.35, metallic=0.8) for r in rails)),
        collision_parts=tuple(CollisionPart(m) for m in (body, *rails)),
        density=1330.0,
        solid=solid,
        info={"kind": "cubesat", "extents": solid.extents.tolist()},
    )


DATASET_OBJECTS = {
    "sample_tube": make_sample_tube,
    "profile_peg_short": lambda: make_profile_peg(PROFILE_PEG_LENGTHS["short"]),
    "profile_peg_long": lambda: make_profile_peg(PROFILE_PEG_LENGTHS["long"]),
    "profile_socket": make_profile_socket,
    "cubesat_1u": lambda: make_cubesat("1u"),
    "cubesat_3u": lambda: make_cubesat("3u"),
}


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
