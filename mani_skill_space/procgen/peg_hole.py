"""Peg and hole pairs from one seed, with the hole's task frames and the profile's rotational symmetry.

A peg is a prism or a frustum over a convex profile: a circle (32 sides) with probability 1/3, otherwise a
regular polygon of 3-12 sides; radius 10-25 mm, height 40-80 mm, taper 0-0.25 (the tip's radius is
``1 - taper`` times the head's), and a cross-section squashed by an aspect of 0.25-1 along a random direction.
The peg is one convex part: its collision shape is exact.

The hole is cut into a 0.15 x 0.15 x 0.12 m module block as the peg's own shape grown by the clearance, at a
random offset (up to 5 cm) and tilt (up to 20 deg) and 0.25-0.75 of the peg's height deep (capped so that 30
mm of the peg stays out for the gripper's fingers). The block minus the bore is split exactly into convex
pieces along the bore's faces (``polytope.subtract_convex``). The hole's frames: ``entrance`` on the block's
top face on the bore axis, ``bottom`` at the bore's floor; both with z out of the hole along its axis and x
along the profile's reference direction. The peg's ``tip`` frame (z into the peg, x the same reference
direction) coincides with ``bottom`` when the peg is fully inserted (up to the clearance).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np
import trimesh

from mani_skill_space.kwarg_checks import KwargError
from mani_skill_space.procgen.asset import Asset, CollisionPart, VisualPart, solid_difference
from mani_skill_space.procgen.polytope import convex_mesh, subtract_convex_meshes

CIRCLE_SIDES = 32
"""A circular profile's polygon: 64 hull vertices, within PhysX's GPU limit for convex meshes."""
BORE_CIRCLE_SIDES = 16
"""A circular bore is the 16-gon circumscribing the grown circle: it holds the peg at any twist with at least
the clearance everywhere (0.5 mm more in its corners) and needs half the collision pieces."""
MODULE_HALF_SIZE = 0.075
MODULE_HEIGHT = 0.12
MIN_WALL = 0.005
FINGER_ROOM = 0.03
"""Length of peg that stays above the entrance when fully inserted, for the gripper's fingers."""
MAX_OFFSET = 0.05
MAX_TILT = np.radians(20.0)
PEG_DENSITY = 2000.0
METAL_FRICTION = 0.3
"""Machined metal on metal. (The scene default of 1.0, the reference's, makes a peg wedge in a 1 mm
clearance hole at the slightest tilt.)"""
DEFAULT_CLEARANCE = 0.001
MAX_CLEARANCE = 0.007
"""The widest clearance (m) for which every pair the generator can draw fits its module with ``MIN_WALL`` walls.
The tightest pair has the sharpest bore corner there is, a 25 mm triangle squashed to 0.25 across one corner (the
mitred corner of its bore grows ~7x the clearance), in the deepest hole (50 mm) tilted 20 deg about both x and y:
it stops fitting at 7.4 mm (found by a search over profile, squash and tilt; ``tests/test_inputs.py`` checks that
it fits at 7 mm and not at 8 mm, and that random pairs fit at 7 mm)."""
BORE_EXTENSION = 0.3
"""How far the bore's convex solid reaches past the peg's head (well out of the block)."""

PEG_COLOR = (0.85, 0.55, 0.15, 1.0)
MODULE_COLOR = (0.55, 0.58, 0.62, 1.0)


@dataclass(frozen=True)
class PegProfile:
    sides: int
    """Polygon sides; ``CIRCLE_SIDES`` stands for a circle."""
    circle: bool
    radius: float
    height: float
    taper: float
    aspect: float
    aspect_angle: float

    @property
    def symmetry_order(self) -> int:
        """Rotations about the axis that map the peg onto itself: n for an n-fold profile, 0 for a continuous
        symmetry (an unsquashed circle). Squashing (aspect < 1) keeps only the half turn of even polygons and
        circles."""
        if self.aspect == 1.0:
            return 0 if self.circle else self.sides
        return 2 if (self.circle or self.sides % 2 == 0) else 1

    def outline(self, scale: float = 1.0, grow: float = 0.0, bore: bool = False) -> np.ndarray:
        """(k, 2) vertices of the cross-section at ``scale`` of the radius, pushed out by ``grow`` metres; for a
        ``bore``, a circle becomes its circumscribed ``BORE_CIRCLE_SIDES``-gon."""
        sides, phase, radius = self.sides, 0.0, self.radius * scale
        if bore and self.circle:
            sides, phase = BORE_CIRCLE_SIDES, np.pi / BORE_CIRCLE_SIDES
            radius /= np.cos(np.pi / BORE_CIRCLE_SIDES)
        angles = phase + np.arange(sides) * 2 * np.pi / sides
        points = np.stack([np.cos(angles), np.sin(angles)], axis=1) * radius
        c, s = np.cos(self.aspect_angle), np.sin(self.aspect_angle)
        rotation = np.array([[c, -s], [s, c]])
        points = points @ rotation @ np.diag([1.0, self.aspect]) @ rotation.T
        return _grow_convex_polygon(points, grow) if grow else points


def sample_profile(rng: np.random.Generator) -> PegProfile:
    circle = bool(rng.uniform() < 1 / 3)
    return PegProfile(
        sides=CIRCLE_SIDES if circle else int(rng.integers(3, 13)),
        circle=circle,
        radius=float(rng.uniform(0.010, 0.025)),
        height=float(rng.uniform(0.04, 0.08)),
        taper=float(rng.uniform(0.0, 0.25)),
        aspect=float(rng.uniform(0.25, 1.0)),
        aspect_angle=float(rng.uniform(0.0, np.pi)),
    )


def peg_points(profile: PegProfile, grow: float = 0.0, extend: float = 0.0, bore: bool = False) -> np.ndarray:
    """Vertices of the peg in its tip frame (tip face at z = 0, head at z = height), optionally grown by
    ``grow`` (perpendicular to the slanted sides) and continued ``extend`` past the head as a prism; ``bore``
    gives the outline of the hole for this peg (see ``PegProfile.outline``)."""
    slant = np.arctan(profile.radius * profile.taper / profile.height)
    grow = grow / np.cos(slant)
    tip = profile.outline(1.0 - profile.taper, grow, bore)
    head = profile.outline(1.0, grow, bore)
    layers = [np.c_[tip, np.zeros(len(tip))], np.c_[head, np.full(len(head), profile.height)]]
    if extend:
        layers.append(np.c_[head, np.full(len(head), profile.height + extend)])
    return np.concatenate(layers)


def make_peg(profile: PegProfile, name: str = "peg") -> Asset:
    points = peg_points(profile)
    mesh = convex_mesh(points)
    com = mesh.center_mass
    mesh.apply_translation(-com)
    tip = np.eye(4)
    tip[:3, 3] = -com
    ends = [tip]
    if profile.taper == 0.0:  # both ends fit: the head end, entering first, is the same shape
        ends.append(_head_frame(tip, profile.height))
    return Asset(
        name=name,
        visual_parts=(VisualPart(mesh, PEG_COLOR, roughness=0.5, metallic=0.3, flat_shading=not profile.circle),),
        collision_parts=(CollisionPart(mesh),),
        density=PEG_DENSITY,
        friction=METAL_FRICTION,
        frames={f"end_{i}": frame for i, frame in enumerate(ends)},
        info={
            "symmetry_order": profile.symmetry_order,
            "ends": len(ends),
            "radius": profile.radius,
            "height": profile.height,
            "profile": {"sides": 0 if profile.circle else profile.sides, "taper": profile.taper, "aspect": profile.aspect},
        },
    )


@dataclass(frozen=True)
class HoleLayout:
    """Where a module's bore goes (all that ``make_hole_module`` draws), before the block is cut: cheap, so that a
    pair's solvability checks can turn it down without cutting a module (``build_hole_module``)."""

    rotation: np.ndarray
    depth: float
    entrance: np.ndarray
    cavity: np.ndarray
    """The bore's convex solid in the module's frame."""
    clearance: float
    symmetry_order: int

    @property
    def bottom(self) -> np.ndarray:
        """The bore floor's frame (the module's ``bottom`` frame)."""
        return _frame(self.rotation, self.entrance - self.depth * self.rotation[:, 2])


def hole_layout(profile: PegProfile, rng: np.random.Generator, clearance: float = DEFAULT_CLEARANCE) -> HoleLayout:
    """The bore's tilt, depth and offset for ``profile``, drawn from ``rng``."""
    clearance = check_clearance(clearance)
    rotation = _tilt_rotation(rng)
    depth = _hole_depth(rng, profile)
    cavity_local = peg_points(profile, grow=clearance, extend=BORE_EXTENSION, bore=True)
    # place the bore so its axis meets the top face at the entrance and its floor lies `depth` below
    centred = _place(cavity_local, rotation, entrance=np.array([0.0, 0.0, MODULE_HEIGHT]), depth=depth)
    low, high = _offset_range(centred)
    offset = np.array([rng.uniform(low[0], high[0]), rng.uniform(low[1], high[1]), 0.0])
    entrance = np.array([0.0, 0.0, MODULE_HEIGHT]) + offset
    return HoleLayout(rotation, depth, entrance, centred + offset, clearance, profile.symmetry_order)


def build_hole_module(layout: HoleLayout) -> Asset:
    """The module block (origin at the centre of its base) with the bore of ``layout`` cut into it."""
    block = _box_vertices()
    return Asset(
        name="hole_module",
        visual_parts=(VisualPart(solid_difference(convex_mesh(block), convex_mesh(layout.cavity)), MODULE_COLOR, roughness=0.6, metallic=0.4),),
        collision_parts=tuple(CollisionPart(piece) for piece in subtract_convex_meshes(block, layout.cavity)),
        friction=METAL_FRICTION,
        frames={"entrance": _frame(layout.rotation, layout.entrance), "bottom": layout.bottom},
        info={
            "depth": layout.depth,
            "clearance": layout.clearance,
            "symmetry_order": layout.symmetry_order,
            "module_size": [2 * MODULE_HALF_SIZE] * 2 + [MODULE_HEIGHT],
        },
    )


def make_hole_module(profile: PegProfile, rng: np.random.Generator, clearance: float = DEFAULT_CLEARANCE) -> Asset:
    """The module block (origin at the centre of its base) with a bore for ``profile``."""
    return build_hole_module(hole_layout(profile, rng, clearance))


def check_clearance(clearance: float, maximum: float = MAX_CLEARANCE, limited_by: str = f"every procedural hole module keeps {MIN_WALL * 1000:g} mm walls") -> float:
    """``clearance`` as a float if it is a number in ``(0, maximum]`` metres: positive, since a peg cannot enter a
    hole of its own size, and at most what the module's geometry holds (``limited_by`` says what that is)."""
    if isinstance(clearance, bool) or not isinstance(clearance, numbers.Real) or not 0.0 < float(clearance) <= maximum:
        raise KwargError(
            "clearance", f"clearance must be positive and at most {maximum:.5g} m (the widest for which {limited_by}): valid range (0, {maximum:.5g}] m, got {clearance!r}"
        )
    return float(clearance)


def bore_fits(profile: PegProfile, rotation: np.ndarray, depth: float, clearance: float) -> bool:
    """Whether the bore for ``profile`` with ``clearance``, its axis turned by ``rotation`` and its floor ``depth``
    below the entrance, fits the module block with ``MIN_WALL`` walls at some offset (what ``make_hole_module``
    requires; ``MAX_CLEARANCE`` is the widest clearance at which every drawn pair passes)."""
    cavity = _place(peg_points(profile, grow=clearance, extend=BORE_EXTENSION, bore=True), rotation, np.array([0.0, 0.0, MODULE_HEIGHT]), depth)
    try:
        _offset_range(cavity)
    except ValueError:
        return False
    return True


def make_peg_hole_pair(seed: int, clearance: float = DEFAULT_CLEARANCE) -> tuple[Asset, Asset]:
    peg, layout = peg_and_hole_layout(seed, clearance)
    return peg, build_hole_module(layout)


def peg_and_hole_layout(seed: int, clearance: float = DEFAULT_CLEARANCE) -> tuple[Asset, HoleLayout]:
    """``make_peg_hole_pair``'s peg and its hole's layout (``build_hole_module`` cuts the module)."""
    rng = np.random.default_rng(int(seed))
    profile = sample_profile(rng)
    return make_peg(profile, name=f"peg_{seed}"), hole_layout(profile, rng, clearance)


def _hole_depth(rng: np.random.Generator, profile: PegProfile) -> float:
    fraction = rng.uniform(0.25, 0.75)
    return float(min(fraction * profile.height, profile.height - FINGER_ROOM))


def _tilt_rotation(rng: np.random.Generator) -> np.ndarray:
    roll, pitch = rng.uniform(-MAX_TILT, MAX_TILT, 2)
    yaw = rng.uniform(-np.pi, np.pi)
    return _rot_z(yaw) @ _rot_y(pitch) @ _rot_x(roll)


def _place(points: np.ndarray, rotation: np.ndarray, entrance: np.ndarray, depth: float) -> np.ndarray:
    """Peg-shaped points (tip frame) turned by ``rotation`` with the tip ``depth`` below ``entrance`` on the axis."""
    bottom = entrance - depth * rotation[:, 2]
    return points @ rotation.T + bottom


def _offset_range(cavity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Entrance offsets that keep the bore's part inside the block at least ``MIN_WALL`` from the sides."""
    inside = cavity[cavity[:, 2] <= MODULE_HEIGHT]
    below_top = _section_at_top(cavity)
    extent = np.concatenate([inside[:, :2], below_top]) if len(below_top) else inside[:, :2]
    limit = MODULE_HALF_SIZE - MIN_WALL
    low = np.maximum(-MAX_OFFSET, -limit - extent.min(axis=0))
    high = np.minimum(MAX_OFFSET, limit - extent.max(axis=0))
    if np.any(low > high) or cavity[:, 2].min() < MIN_WALL:
        raise ValueError("the bore does not fit in the module block")
    return low, high


def _section_at_top(cavity: np.ndarray) -> np.ndarray:
    from mani_skill_space.procgen.polytope import clip

    below = clip(cavity, np.array([0.0, 0.0, 1.0]), MODULE_HEIGHT)
    return below[np.isclose(below[:, 2], MODULE_HEIGHT)][:, :2] if len(below) else below[:, :2]


def module_block() -> trimesh.Trimesh:
    """The hole module's block before its hole is cut (origin at the centre of its base)."""
    return convex_mesh(_box_vertices())


def _box_vertices() -> np.ndarray:
    a, h = MODULE_HALF_SIZE, MODULE_HEIGHT
    return np.array([[x, y, z] for x in (-a, a) for y in (-a, a) for z in (0.0, h)])


def _grow_convex_polygon(points: np.ndarray, distance: float) -> np.ndarray:
    """Move every edge of a convex polygon (counter-clockwise) outward by ``distance`` (mitred corners)."""
    previous, following = np.roll(points, 1, axis=0), np.roll(points, -1, axis=0)
    out_before = _outward_normals(previous, points)
    out_after = _outward_normals(points, following)
    bisector = out_before + out_after
    scale = distance / np.einsum("ij,ij->i", bisector, out_after)
    return points + bisector * scale[:, None]


def _outward_normals(start: np.ndarray, end: np.ndarray) -> np.ndarray:
    edge = end - start
    normal = np.stack([edge[:, 1], -edge[:, 0]], axis=1)
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def _frame(rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
    frame = np.eye(4)
    frame[:3, :3], frame[:3, 3] = rotation, position
    return frame


def _head_frame(tip: np.ndarray, height: float) -> np.ndarray:
    """The head end seen as a tip: at the head face, z pointing back into the peg (a half turn about x)."""
    frame = tip @ np.diag([1.0, -1.0, -1.0, 1.0])
    frame[:3, 3] = tip[:3, 3] + tip[:3, 2] * height
    return frame


def _rot_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
