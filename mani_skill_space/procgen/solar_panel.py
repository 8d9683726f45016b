"""Solar Panel Assembly assets: four sockets on posts, the pegs that fit them, and a panel with four receptacles.

Layout (the reference's): sockets at (+-0.1, +-0.2) m from the panel's target centre, scaled with the panel;
the two nearer the arm take long pegs, the two farther take short ones (long = short + 0.1 m). Every socket's
floor sits so that the inserted pegs' tops are level at ``SEAT_HEIGHT``: the panel, lowered onto them, rests
its plate on all four tops while its receptacles (square tubes under the plate) slide over them.

- ``make_socket_base(layout)``: one static asset with the four posts; each post minus its bore is split
  exactly into convex pieces (``polytope.subtract_convex``), as for Peg-in-Hole's module. Frames
  ``entrance_i`` / ``bottom_i`` per socket (z up, x along the profile's reference direction), origin at the
  panel's target centre on the ground.
- ``make_panel(layout)``: the panel, centred on its centre of mass; frames ``seat`` (plate bottom centre: the
  pose that must reach the target) and ``handle`` (the grasp bar's centre, x across the bar).
- ``make_solar_layout(seed)`` / ``dataset_layout()``: the consistent set (peg profile and lengths, socket
  depth, panel scale). Procedural layouts vary the profile (3-8-gon, radius 10-16 mm, squashed by
  0.6-1), the pegs' lengths, the sockets' depth and the panel's size; receptacles always fit the pegs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import trimesh

from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart, box_mesh, solid_difference, solid_union, translation_frame
from mani_skill_space.procgen.peg_hole import (
    BORE_EXTENSION,
    DEFAULT_CLEARANCE,
    METAL_FRICTION,
    MODULE_COLOR,
    PegProfile,
    check_clearance,
    make_peg,
    peg_points,
)
from mani_skill_space.procgen.polytope import convex_mesh, subtract_convex_meshes

SEAT_HEIGHT = 0.28
"""Height (m) above the ground of the inserted pegs' tops, where the panel's plate comes to rest."""
SOCKET_OFFSETS = np.array([[-0.1, 0.2], [-0.1, -0.2], [0.1, 0.2], [0.1, -0.2]])
"""Socket centres relative to the panel's target centre (reference layout, before the panel's scale):
sockets 0 and 1 (nearer the arm) take long pegs, 2 and 3 short ones."""
LONG_SOCKETS = (0, 1)
MAX_SIDES = 8
"""Procedural profiles are 3-8 sided polygons: four long pegs lying side by side with rounder profiles (or
circles) would roll off their starting places on the flat ground."""
POST_HALF_WIDTH = 0.025
"""The reference socket's 50 x 50 mm post."""
PROFILE_RADIUS = (0.010, 0.016)
PROFILE_ASPECT = (0.6, 1.0)
"""Ranges of the procedural pegs' profile: circumradius (m) and the squash of the cross-section."""
PEG_LENGTH_STEP = 0.1
"""A long peg is this much longer than a short one (reference: 0.1 and 0.2 m)."""

PANEL_SIZE = (0.27, 0.47)
"""The reference's ~0.233 x 0.425 m panel, grown to cover its receptacles (which sit on the reference's
socket spacing, 0.2 x 0.4 m, and are ~70 mm wide at their funnels' mouths)."""
PANEL_THICKNESS = 0.012
PANEL_DENSITY = 300.0
"""Aluminium honeycomb with cells and cover glass: about 0.4 kg for the reference size."""
RECEPTACLE_PLAY = 0.004
"""Radial room (m) between a peg's corners and its receptacle's inner walls."""
RECEPTACLE_LENGTH = 0.025
RECEPTACLE_WALL = 0.003
FLARE_LENGTH = 0.02
FLARE_ANGLE = np.radians(45.0)
RECEPTACLE_DEPTH = RECEPTACLE_LENGTH + FLARE_LENGTH * np.cos(FLARE_ANGLE) + RECEPTACLE_WALL
"""How far (m) below the plate the receptacles' funnels reach."""
HANDLE_LENGTH = 0.12
HANDLE_SECTION = 0.016
OVERLAP = 0.002
"""Parts reach this far into the parts they join, so that their union is one solid."""
HANDLE_STANDOFF = 0.045
"""The grasp bar stands this far above the plate (to its underside): room for the gripper's fingertips."""

PANEL_FRAME_COLOR = (0.72, 0.74, 0.77, 1.0)
CELL_COLOR = (0.08, 0.12, 0.38, 1.0)

MIN_POST_WALL = RECEPTACLE_WALL
"""The thinnest socket wall the generator makes: as thin as the panel's receptacle walls, the thinnest part the task
already relies on (thinner convex slivers cook poorly and let a pushed peg through)."""


def _max_clearance() -> float:
    """The widest clearance (m) for which every procedural socket keeps ``MIN_POST_WALL`` walls. A bore is the
    profile grown by the clearance with mitred corners: a corner of half-angle a moves out by clearance / sin(a). The
    sharpest corner drawn is a triangle's, squashed across it to the smallest aspect s (tan a = s tan 30 deg); with
    the squash across it, that corner stays at the largest radius R and can point straight at a post's side, so the
    bore reaches R + clearance / sin(a) from the socket's centre."""
    half_angle = np.arctan(PROFILE_ASPECT[0] * np.tan(np.pi / 6))
    return float((POST_HALF_WIDTH - MIN_POST_WALL - PROFILE_RADIUS[1]) * np.sin(half_angle))


MAX_CLEARANCE = _max_clearance()
"""1.96 mm: a 16 mm triangle squashed to 0.6 grows its sharpest bore corner 3.06 mm per mm of clearance. Beyond the
limit walls thin out, then the bore cuts through its post (the sharpest profiles from 2.9 mm; seed 0's octagon
from 11 mm; at 30 mm only the floors are left)."""


@dataclass(frozen=True)
class SolarLayout:
    """Everything the four assets must agree on."""

    profile: PegProfile
    short_length: float
    depth: float
    clearance: float
    panel_scale: tuple[float, float]
    square_bore: bool = False
    """The dataset's square profile peg: a box-shaped bore aligned with the peg's faces."""

    @property
    def long_length(self) -> float:
        return self.short_length + PEG_LENGTH_STEP

    @property
    def socket_xy(self) -> np.ndarray:
        return SOCKET_OFFSETS * np.asarray(self.panel_scale)

    @property
    def peg_lengths(self) -> list[float]:
        return [self.long_length if i in LONG_SOCKETS else self.short_length for i in range(len(SOCKET_OFFSETS))]

    @property
    def circumradius(self) -> float:
        return float(np.linalg.norm(self.profile.outline(), axis=1).max())


def check_socket_clearance(clearance: float) -> float:
    """``clearance`` as a float if the procedural sockets hold it: positive and at most ``MAX_CLEARANCE``."""
    return check_clearance(clearance, MAX_CLEARANCE, f"every procedural socket keeps {MIN_POST_WALL * 1000:g} mm walls")


def make_solar_layout(seed: int, clearance: float = DEFAULT_CLEARANCE) -> SolarLayout:
    rng = np.random.default_rng(int(seed))
    profile = PegProfile(
        sides=int(rng.integers(3, MAX_SIDES + 1)),
        circle=False,
        radius=float(rng.uniform(*PROFILE_RADIUS)),
        height=0.0,
        taper=0.0,
        aspect=float(rng.uniform(*PROFILE_ASPECT)),
        aspect_angle=float(rng.uniform(0.0, np.pi)),
    )
    return SolarLayout(
        profile=profile,
        short_length=float(rng.uniform(0.09, 0.12)),
        depth=float(rng.uniform(0.02, 0.03)),
        clearance=check_socket_clearance(clearance),
        panel_scale=(float(rng.uniform(0.9, 1.1)), float(rng.uniform(0.9, 1.1))),
    )


def dataset_layout(short_length: float, width: float, clearance: float, depth: float) -> SolarLayout:
    """The reference: square profile pegs of ``width``, sockets ``depth`` deep, the reference panel."""
    square = PegProfile(sides=4, circle=False, radius=width / np.sqrt(2), height=0.0, taper=0.0, aspect=1.0, aspect_angle=0.0)
    return SolarLayout(profile=square, short_length=short_length, depth=depth, clearance=clearance, panel_scale=(1.0, 1.0), square_bore=True)


def make_solar_pegs(layout: SolarLayout, seed: int) -> list[Asset]:
    """The four (procedural) pegs in socket order: two long, two short, one profile."""
    return [make_peg(dataclasses.replace(layout.profile, height=length), name=f"solar_peg_{seed}_{i}") for i, length in enumerate(layout.peg_lengths)]


def socket_frames(layout: SolarLayout) -> dict[str, np.ndarray]:
    """Each socket's ``bottom_i`` and ``entrance_i`` frame (z up, out of the socket) in the base's frame."""
    frames = {}
    for i, ((x, y), length) in enumerate(zip(layout.socket_xy, layout.peg_lengths)):
        bottom_z = SEAT_HEIGHT - length
        frames[f"bottom_{i}"] = translation_frame((x, y, bottom_z))
        frames[f"entrance_{i}"] = translation_frame((x, y, bottom_z + layout.depth))
    return frames


def make_socket_base(layout: SolarLayout) -> Asset:
    """The four socket posts (static), origin on the ground below the panel's target centre."""
    collision, visual, frames = [], [], socket_frames(layout)
    for i, (x, y) in enumerate(layout.socket_xy):
        bottom, top_z = frames[f"bottom_{i}"][:3, 3], frames[f"entrance_{i}"][2, 3]
        post = np.array([[x + sx * POST_HALF_WIDTH, y + sy * POST_HALF_WIDTH, z] for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, top_z)])
        cavity = _bore_points(layout) + bottom
        collision += [CollisionPart(piece) for piece in subtract_convex_meshes(post, cavity)]
        visual.append(solid_difference(convex_mesh(post), convex_mesh(cavity)))
    return Asset(
        name="socket_base",
        visual_parts=tuple(VisualPart(m, MODULE_COLOR, roughness=0.6, metallic=0.4) for m in visual),
        collision_parts=tuple(collision),
        friction=METAL_FRICTION,
        frames=frames,
        info={"depth": layout.depth, "clearance": layout.clearance, "symmetry_order": layout.profile.symmetry_order, "seat_height": SEAT_HEIGHT},
    )


def _bore_points(layout: SolarLayout) -> np.ndarray:
    """The bore's convex solid in the socket's bottom frame, reaching well out of the post."""
    if layout.square_bore:
        half = layout.profile.radius / np.sqrt(2) + layout.clearance
        return np.array([[sx * half, sy * half, z] for sx in (-1, 1) for sy in (-1, 1) for z in (0.0, BORE_EXTENSION)])
    profile = dataclasses.replace(layout.profile, height=layout.depth)
    return peg_points(profile, grow=layout.clearance, extend=BORE_EXTENSION, bore=True)


def make_panel(layout: SolarLayout, name: str = "solar_panel") -> Asset:
    """The panel: a plate with a grasp bar on top and a square receptacle tube under it over each socket."""
    half_x, half_y = np.asarray(PANEL_SIZE) * np.asarray(layout.panel_scale) / 2
    plate = box_mesh((half_x, half_y, PANEL_THICKNESS / 2), (0.0, 0.0, PANEL_THICKNESS / 2))
    cells = box_mesh((half_x - 0.01, half_y - 0.01, 0.0005), (0.0, 0.0, PANEL_THICKNESS + 0.0005))
    bar_z = PANEL_THICKNESS + HANDLE_STANDOFF + HANDLE_SECTION / 2
    bar = box_mesh((HANDLE_SECTION / 2, HANDLE_LENGTH / 2, HANDLE_SECTION / 2), (0.0, 0.0, bar_z))
    standoffs = [
        box_mesh((HANDLE_SECTION / 2, HANDLE_SECTION / 2, HANDLE_STANDOFF / 2 + OVERLAP), (0.0, side * (HANDLE_LENGTH / 2 - HANDLE_SECTION / 2), PANEL_THICKNESS + HANDLE_STANDOFF / 2))
        for side in (-1, 1)
    ]
    walls = [w for x, y in layout.socket_xy for w in _receptacle_walls(x, y, layout.circumradius + RECEPTACLE_PLAY)]
    frame_parts = [plate, bar, *standoffs, *walls]
    solid = solid_union(frame_parts)
    com = solid.center_mass
    for mesh in [solid, cells, *frame_parts]:
        mesh.apply_translation(-com)
    seat = translation_frame(-com)
    handle = translation_frame(np.array([0.0, 0.0, bar_z]) - com)
    return Asset(
        name=name,
        visual_parts=(VisualPart(cells, CELL_COLOR, roughness=0.25, metallic=0.6), *(VisualPart(m, PANEL_FRAME_COLOR, roughness=0.4, metallic=0.6) for m in frame_parts)),
        collision_parts=tuple(CollisionPart(m) for m in frame_parts),
        density=PANEL_DENSITY,
        solid=solid,
        frames={"seat": seat, "handle": handle},
        info={"size": [2 * half_x, 2 * half_y, PANEL_THICKNESS], "receptacle_inner_half_width": layout.circumradius + RECEPTACLE_PLAY},
    )


def _receptacle_walls(x: float, y: float, inner_half: float) -> list[trimesh.Trimesh]:
    """A square tube hanging under the plate around (x, y), ending in a funnel: four walls reaching into the
    plate (and into each other at the corners, so that their union is one solid), and below each a plate
    flaring outward by ``FLARE_ANGLE``, which catches a peg leaning in its socket and rights it."""
    w = RECEPTACLE_WALL
    half_height = (RECEPTACLE_LENGTH + OVERLAP) / 2
    z = -RECEPTACLE_LENGTH + half_height
    along = inner_half + w
    parts = []
    for angle in np.arange(4) * np.pi / 2:  # the wall on the +x side, turned to each side in turn
        turn = trimesh.transformations.rotation_matrix(angle, [0, 0, 1])
        wall = box_mesh((w / 2, along, half_height), (inner_half + w / 2, 0.0, z))
        flare = box_mesh((w / 2, along + FLARE_LENGTH * np.sin(FLARE_ANGLE), FLARE_LENGTH / 2 + w / 2))
        flare.apply_transform(trimesh.transformations.rotation_matrix(FLARE_ANGLE, [0, 1, 0]))
        flare.apply_translation((inner_half + w / 2 + FLARE_LENGTH / 2 * np.sin(FLARE_ANGLE), 0.0, -RECEPTACLE_LENGTH - FLARE_LENGTH / 2 * np.cos(FLARE_ANGLE)))
        for mesh in (wall, flare):
            mesh.apply_transform(turn)
            mesh.apply_translation((x, y, 0.0))
            parts.append(mesh)
    return parts
