"""Peg insertion, shared by PegInHoleAssembly-v1 and SolarPanelAssembly-v1 and by their oracles.

Both tasks hold ``k`` pegs and ``k`` holes per env (Peg-in-Hole: one of each; Solar Panel: four pegs and the
four sockets of the base) in a ``PegInsertion``: batched tensors with a leading ``num_envs`` dim, then the
peg or hole index. Its frames are public and documented, so that rewards, success and the oracles all read
the same geometry:

- ``hole_entrance`` and ``hole_bottom`` (n, k, 4, 4): world poses of each hole's mouth and floor, z pointing
  out of the hole, x the profile's reference direction; ``hole_depth`` (n, k) is the distance between them.
- ``peg_ends`` (n, k, 2, 4, 4): poses of each peg's insertable ends in the peg's own frame, z pointing into
  the peg, x the profile's reference direction; ``peg_end_valid`` (n, k, 2) says which exist (a tapered peg
  goes in by its narrow end only; the second slot then repeats the first).
- ``symmetry_order`` (n, k): the profile's rotational symmetry (0: round, any twist fits).
- ``peg_radius`` and ``peg_height`` (n, k).

Success is the same in both tasks: an insertable end at least ``INSERTED_FRACTION`` of the depth in, within
the peg's radius of the hole's axis, and the axes aligned within ``ALIGNMENT_TOLERANCE``.

Sockets latch (both tasks, every domain): a peg that counts as inserted is pulled toward the hole's bottom along
its axis with ``LATCH_ACCELERATION`` and damped by ``LATCH_DAMPING`` (``latch_force``), the way real orbital
hardware holds parts with a detent; in orbit a released peg would otherwise drift out of its 1 mm clearance.
The force is applied to the peg's body at every physics step (``SpaceManipulationEnv._latch_forces``), on the
CPU and GPU simulators alike; no body or joint is added.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np
import torch
from mani_skill.utils.geometry.rotation_conversions import quaternion_to_matrix

from mani_skill_space.envs.base import RestingPlacement, turned_about_z
from mani_skill_space.geometry import insertion_measures, pose_matrix, relative_pose
from mani_skill_space.procgen.asset import Asset
from mani_skill_space.rewards import RewardTerm, band_distance

INSERTED_FRACTION = 0.9
ALIGNMENT_TOLERANCE = np.radians(5.0)
PEG_LIFT_BAND = (0.05, 0.55)
"""A lifted peg earns the lift term 0.05-0.55 m above where it lay."""
PEG_DROP_CLEARANCE = 0.0005
PEG_HEADING_JITTER = np.pi / 16
"""A peg lies pointing at the arm (its tip, the end that goes in, toward the arm) within this angle, as in the
reference (a fixed heading +- pi/16). Lying across, a grasp of its side would turn the hand's long side toward
the rover's front."""
REACH_GRASP_TILT = np.radians(45.0)
HAND_OUTWARD_MIN = -0.3
"""``reachable_faces``: the cosine of the angle between the hand's approach, holding the peg over its hole, and the
horizontal direction from the arm's base to the hole must be at least this. Measured with the oracle on
procedural pairs (seeds 50000-50099, Earth): of the placements below it, 1 in 19 was inserted; of those above,
3 in 4."""
MIN_GRIP_HEIGHT = 0.010
"""m: ``grippable_faces``: a peg lies only on a side from which it rises at least this high. The Panda's finger pads
are 18.5 mm tall and its fingertips must stay above the ground, so a flatter peg is held by its thin edge over
less than half of the pads, and turns or slips out of the grip as the arm swings it (measured with the oracle on
procedural pairs, seeds 60000-60059 in every domain: pegs lying under 10 mm tall were inserted in 3 of 16
episodes, the others in 88%). A squashed peg that can stand on its narrow side lies that way instead."""
MIN_SIDE_HEIGHT = 0.003
"""m: ``grippable_faces``: the peg's widest part across its axis (where the closing fingers meet it, within 1 mm of
its farthest) must reach at least this high above the ground on both sides. A peg that is widest only at its base,
such as a triangle lying on a face, is met by the fingers at its bottom edges only, and the squeeze wedges it out of
the grip once it is off the ground (on seeds 60000-60059 in every domain the oracle inserted 73% of the 44 pegs
lying so, 91% of the others)."""
SIDE_TOLERANCE = 0.001
"""m: the peg's points within this of its farthest point across the fingers are where a finger meets it."""
LYING_AXIS = np.array([0.0, 0.0, 1.0])
"""A peg lies on a side, never on an end: its axis (z) is never the resting direction."""


LATCH_ACCELERATION = 9.81
"""m/s^2: a socket's latch pulls a seated part into its seat as hard as Earth's gravity would pull it down (about
1 N for a 0.1 kg peg): enough to keep a released part seated in orbit, far less than the arm can pull."""
LATCH_DAMPING = 10.0
"""1/s: the latch also damps the seated part's motion (a detent's friction), so a released part settles."""


def latch_force(engaged: torch.Tensor, into_seat: torch.Tensor, velocity: torch.Tensor, mass: torch.Tensor) -> torch.Tensor:
    """Force (..., 3) of a latch on a part: where ``engaged`` (...), the part's ``mass`` (...) times
    ``LATCH_ACCELERATION`` along ``into_seat`` (..., 3, unit) less ``LATCH_DAMPING`` times its ``velocity``
    (..., 3); zero elsewhere (a part that is not seated is not captured)."""
    force = mass[..., None] * (LATCH_ACCELERATION * into_seat - LATCH_DAMPING * velocity)
    return torch.where(engaged[..., None], force, torch.zeros_like(force))


def seated_pairs(insertion: "PegInsertion", measures: dict[str, torch.Tensor], fits: torch.Tensor) -> torch.Tensor:
    """(n, pegs, holes) from ``all_pair_measures``: the peg is inserted in the hole and aligned with it, and ``fits``
    (pegs, holes) says that peg may count in that hole."""
    return is_inserted(measures, insertion.peg_radius[:, :, None]) & is_aligned(measures) & fits


def pegs_latched_in_holes(pegs, masses, seated: torch.Tensor, hole_bottoms: torch.Tensor) -> list:
    """The latch forces ``(peg, force)`` of every peg (its actor and mass (n,)) in the hole it is ``seated`` in
    (``seated_pairs``), pulling it along that hole's axis into ``hole_bottoms`` (n, holes, 4, 4); zero where it is
    in none."""
    into_holes = -hole_bottoms[:, :, :3, 2]
    rows = torch.arange(len(seated), device=seated.device)
    return [
        (peg, latch_force(seated[:, i].any(dim=1), into_holes[rows, seated[:, i].int().argmax(dim=1)], peg.linear_velocity, mass))
        for i, (peg, mass) in enumerate(zip(pegs, masses))
    ]


def insertion_terms(prefix: str = "") -> tuple[RewardTerm, ...]:
    """Peg-in-Hole's dense terms (the reference's weights), each name prefixed with ``prefix``."""
    return (
        RewardTerm(f"{prefix}reach", 1.0, sigma=0.25),
        RewardTerm(f"{prefix}grasp", 4.0),
        RewardTerm(f"{prefix}lift", 8.0, sigma=0.05),
        RewardTerm(f"{prefix}align_axis", 8.0, sigma=0.5),
        RewardTerm(f"{prefix}align_twist", 4.0, sigma=0.2),
        RewardTerm(f"{prefix}entrance", 16.0, sigma=0.05),
        RewardTerm(f"{prefix}bottom", 128.0, sigma=0.005),
    )


INSERTION_VALUE = sum(term.weight for term in insertion_terms())
"""What one inserted peg's dense terms add up to at most (169)."""


@dataclass(frozen=True)
class PegInsertion:
    """``k`` pegs and ``k`` holes per env, batched (see the module docstring for the frames)."""

    hole_entrance: torch.Tensor
    hole_bottom: torch.Tensor
    hole_depth: torch.Tensor
    symmetry_order: torch.Tensor
    peg_ends: torch.Tensor
    peg_end_valid: torch.Tensor
    peg_radius: torch.Tensor
    peg_height: torch.Tensor

    @classmethod
    def from_assets(
        cls,
        pegs: Sequence[Sequence[Asset]],
        hole_entrances: Sequence[Sequence[np.ndarray]],
        hole_bottoms: Sequence[Sequence[np.ndarray]],
        hole_depths: Sequence[Sequence[float]],
        symmetry_orders: Sequence[Sequence[int]],
        device,
    ) -> "PegInsertion":
        """From per-env lists (one entry per peg or hole) of peg assets and world hole frames."""
        as_tensor = lambda x: torch.as_tensor(np.asarray(x), dtype=torch.float32, device=device)  # noqa: E731
        return cls(
            hole_entrance=as_tensor(hole_entrances),
            hole_bottom=as_tensor(hole_bottoms),
            hole_depth=as_tensor(hole_depths),
            symmetry_order=torch.as_tensor(np.asarray(symmetry_orders), device=device),
            peg_ends=as_tensor([[[p.frames["end_0"], p.frames.get("end_1", p.frames["end_0"])] for p in env_pegs] for env_pegs in pegs]),
            peg_end_valid=torch.as_tensor([[[True, "end_1" in p.frames] for p in env_pegs] for env_pegs in pegs], device=device),
            peg_radius=as_tensor([[p.info["radius"] for p in env_pegs] for env_pegs in pegs]),
            peg_height=as_tensor([[p.info["height"] for p in env_pegs] for env_pegs in pegs]),
        )

    @property
    def count(self) -> int:
        return self.hole_depth.shape[1]

    def end_frames(self, peg_positions: torch.Tensor, peg_quaternions: torch.Tensor) -> torch.Tensor:
        """World poses (n, k, 2, 4, 4) of the pegs' insertable ends, given the pegs' poses (n, k, 3) and (n, k, 4)."""
        return pose_matrix(peg_positions, peg_quaternions).unsqueeze(2) @ self.peg_ends

    def measures(self, end_frames: torch.Tensor) -> dict[str, torch.Tensor]:
        """``insertion_measures`` of peg i in hole i, each (n, k)."""
        n, k = self.hole_depth.shape
        flat = insertion_measures(
            end_frames.reshape(n * k, 2, 4, 4),
            self.peg_end_valid.reshape(n * k, 2),
            self.hole_entrance.reshape(n * k, 4, 4),
            self.hole_bottom.reshape(n * k, 4, 4),
            self.hole_depth.reshape(n * k),
            self.symmetry_order.reshape(n * k),
        )
        return {name: value.reshape(n, k) for name, value in flat.items()}

    def all_pair_measures(self, end_frames: torch.Tensor) -> dict[str, torch.Tensor]:
        """``insertion_measures`` of every peg in every hole, each (n, k pegs, k holes)."""
        n, k = self.hole_depth.shape
        flat = insertion_measures(
            end_frames[:, :, None].expand(n, k, k, 2, 4, 4).reshape(-1, 2, 4, 4),
            self.peg_end_valid[:, :, None].expand(n, k, k, 2).reshape(-1, 2),
            self.hole_entrance[:, None].expand(n, k, k, 4, 4).reshape(-1, 4, 4),
            self.hole_bottom[:, None].expand(n, k, k, 4, 4).reshape(-1, 4, 4),
            self.hole_depth[:, None].expand(n, k, k).reshape(-1),
            self.symmetry_order[:, None].expand(n, k, k).reshape(-1),
        )
        return {name: value.reshape(n, k, k) for name, value in flat.items()}


def is_inserted(measures: dict[str, torch.Tensor], peg_radius: torch.Tensor) -> torch.Tensor:
    """The end is deep enough and on the hole's axis (``peg_radius`` broadcast to the measures' shape)."""
    return (measures["inserted_fraction"] >= INSERTED_FRACTION) & (measures["lateral_offset"] <= peg_radius)


def is_aligned(measures: dict[str, torch.Tensor]) -> torch.Tensor:
    return measures["axis_angle"] <= ALIGNMENT_TOLERANCE


def insertion_inputs(
    tcp_position: torch.Tensor, peg_position: torch.Tensor, grasped: torch.Tensor, start_height: torch.Tensor, measures: dict[str, torch.Tensor]
) -> dict[str, torch.Tensor]:
    """Inputs of ``insertion_terms()`` (unprefixed names), any batch shape: the TCP (..., 3) and peg (..., 3)
    positions, whether the peg is grasped, the height it lay at and its measures in the hole it goes to."""
    return dict(
        reach=torch.linalg.norm(tcp_position - peg_position, dim=-1),
        grasp=grasped,
        lift=band_distance(peg_position[..., 2] - start_height, *PEG_LIFT_BAND),
        align_axis=1.0 - torch.cos(measures["axis_angle"]),
        align_twist=measures["twist_error"],
        entrance=measures["tip_to_entrance"],
        bottom=measures["tip_to_bottom"],
    )


def peg_placement(pegs: Sequence[Asset], device) -> RestingPlacement:
    """Resting orientations of one peg per env, lying on a side."""
    return RestingPlacement(pegs, device, exclude_axis=LYING_AXIS)


def reachable_faces(placement: RestingPlacement, tip_frames: torch.Tensor, hole_bottoms: torch.Tensor, symmetry_orders: torch.Tensor, arm_base: torch.Tensor) -> torch.Tensor:
    """(n, faces) which of each env's resting faces (``placement``) leave its peg reachable for insertion: taken
    from above as it lies (tip toward the arm, tilted ``REACH_GRASP_TILT`` toward the tip, fingers closing across
    it), it can be held on its hole's axis, at some twist its symmetry allows, with the hand pointing no further
    back toward the arm than ``HAND_OUTWARD_MIN`` (a Panda cannot fold its wrist back over a hole in front of it).
    ``tip_frames`` (n, 4, 4): the insertable end in the peg's frame; ``hole_bottoms`` (n, 4, 4) world;
    ``symmetry_orders`` (n,); ``arm_base`` (3,) world. Padded faces (beyond each env's count) are False."""
    rest = quaternion_to_matrix(placement.quaternions)  # (n, F, 3, 3) peg to world, lying on that face
    tip = rest @ tip_frames[:, None, :3, :3]
    axis = tip[..., :, 2]
    turn = _rotation_z(-torch.atan2(axis[..., 1], axis[..., 0]))  # tip toward the arm: its axis along +x
    tip = turn @ tip
    hand = _top_grasp(tip[..., :, 2], REACH_GRASP_TILT)  # (n, F, 3, 3)
    hand_in_tip = tip.transpose(-1, -2) @ hand
    order = symmetry_orders.clamp(min=0)
    count = torch.where(order == 0, torch.full_like(order, 8), order)  # a round peg: eight twists
    slots = torch.arange(int(count.max()), device=count.device)
    twists = 2 * np.pi * slots[None, :] / count[:, None]  # (n, T)
    over_hole = hole_bottoms[:, None, None, :3, :3] @ _rotation_z(twists)[:, None] @ hand_in_tip[:, :, None]  # (n, F, T, 3, 3)
    outward = hole_bottoms[:, :3, 3] - arm_base
    outward[:, 2] = 0.0
    outward = torch.nn.functional.normalize(outward, dim=-1)
    pointing_out = torch.einsum("nftk,nk->nft", over_hole[..., :, 2], outward)
    usable = (slots[None, :] < count[:, None])[:, None, :] & (pointing_out >= HAND_OUTWARD_MIN)
    real_face = torch.arange(rest.shape[1], device=count.device)[None, :] < placement.counts[:, None]
    return usable.any(dim=-1) & real_face


def grippable_faces(placement: RestingPlacement) -> torch.Tensor:
    """(n, faces) which of each env's resting faces (``placement``) let the fingers take its peg firmly from above:
    lying there it is at least ``MIN_GRIP_HEIGHT`` tall, and its widest part across its axis rises at least
    ``MIN_SIDE_HEIGHT`` above the ground on both sides. Padded faces are False."""
    rest = quaternion_to_matrix(placement.quaternions)  # (n, F, 3, 3) peg to world, lying on each face
    lying = torch.einsum("nfij,npj->nfpi", rest, placement.points)  # every vertex, lying on each face
    heights = lying[..., 2] - lying[..., 2].amin(dim=-1, keepdim=True)
    tall_enough = heights.amax(dim=-1) >= MIN_GRIP_HEIGHT
    axis = rest[..., :, 2]  # the peg's axis (its z), lying roughly level
    across = torch.nn.functional.normalize(torch.stack([-axis[..., 1], axis[..., 0], torch.zeros_like(axis[..., 0])], dim=-1), dim=-1)
    offsets = torch.einsum("nfpi,nfi->nfp", lying, across)
    sides_rise = torch.ones_like(tall_enough)
    for sign in (1.0, -1.0):
        outer = sign * offsets >= (sign * offsets).amax(dim=-1, keepdim=True) - SIDE_TOLERANCE
        sides_rise &= torch.where(outer, heights, torch.zeros_like(heights)).amax(dim=-1) >= MIN_SIDE_HEIGHT
    real_face = torch.arange(rest.shape[1], device=placement.counts.device)[None, :] < placement.counts[:, None]
    return tall_enough & sides_rise & real_face


def insertable_faces(placement: RestingPlacement, tip_frames: torch.Tensor, hole_bottoms: torch.Tensor, symmetry_orders: torch.Tensor, arm_base: torch.Tensor) -> torch.Tensor:
    """(n, faces): the resting faces that pass every solvability check, ``reachable_faces`` (same arguments) and
    ``grippable_faces``: the faces an episode's peg may lie on."""
    return reachable_faces(placement, tip_frames, hole_bottoms, symmetry_orders, arm_base) & grippable_faces(placement)


def allow_insertable_faces(placement: RestingPlacement, pegs: Sequence[Asset]) -> None:
    """Let ``placement`` (one peg per env, ``pegs``) put down only the faces each peg's ``info["insertable_faces"]``
    lists (those that passed its solvability checks when it was drawn)."""
    faces = placement.allowed.shape[1]
    listed = [list(p.info["insertable_faces"]) + [False] * (faces - len(p.info["insertable_faces"])) for p in pegs]
    placement.allow_only(torch.tensor(listed, dtype=torch.bool, device=placement.allowed.device))


def face_checks_of(peg: Asset, hole_bottom: np.ndarray, arm_base: np.ndarray, placement: Optional[RestingPlacement] = None) -> dict[str, torch.Tensor]:
    """Each solvability check's verdict (faces,) on every resting face of one peg asset, for its hole's
    ``hole_bottom`` (world, 4 x 4) and an arm at ``arm_base``, on the CPU: ``reachable`` (``reachable_faces``),
    ``grippable`` (``grippable_faces``) and ``insertable`` (both). ``placement``: the peg's own
    ``peg_placement([peg], "cpu")``, where the caller has it already."""
    as_tensor = lambda x: torch.as_tensor(np.asarray(x), dtype=torch.float32)  # noqa: E731
    placement = peg_placement([peg], "cpu") if placement is None else placement
    reachable = reachable_faces(
        placement, as_tensor(peg.frames["end_0"])[None], as_tensor(hole_bottom)[None], torch.tensor([peg.info["symmetry_order"]]), as_tensor(arm_base)
    )[0]
    grippable = grippable_faces(placement)[0]
    return dict(reachable=reachable, grippable=grippable, insertable=reachable & grippable)


def feasibility_record(draws: int, checks: Sequence[dict[str, torch.Tensor]]) -> dict:
    """What a procedural instance records of its solvability checks (its asset's ``info["feasibility"]``): the draws
    it took, and for each peg its resting faces and how many pass each check (``face_checks_of``)."""
    return {
        "draws": draws,
        "checks": sorted(checks[0]),
        "resting_faces": [len(c["insertable"]) for c in checks],
        **{f"{name}_resting_faces": [int(c[name].sum()) for c in checks] for name in sorted(checks[0])},
    }


def redrawn_seed(seed: int, draw: int) -> int:
    """The asset seed of the ``draw``-th redraw for ``seed`` (the seed itself first), deterministic."""
    return int(seed) if draw == 0 else int(np.random.SeedSequence([int(seed), draw]).generate_state(1)[0] & 0x7FFFFFFF)


def _top_grasp(axis: torch.Tensor, tilt: float) -> torch.Tensor:
    """Hand rotations (..., 3, 3: x, closing, approach columns, ManiSkill's grasp convention) taking a lying peg
    with ``axis`` (..., 3) from above, tilted by ``tilt`` toward the end the axis points away from."""
    up = torch.zeros_like(axis)
    up[..., 2] = 1.0
    closing = torch.nn.functional.normalize(torch.cross(axis, up, dim=-1), dim=-1)
    upward = torch.cross(closing, axis, dim=-1)
    upward = upward * torch.sign(upward[..., 2:3])
    approach = -np.sin(tilt) * axis - np.cos(tilt) * upward
    return torch.stack([torch.cross(closing, approach, dim=-1), closing, approach], dim=-1)


def _rotation_z(angle: torch.Tensor) -> torch.Tensor:
    c, s = torch.cos(angle), torch.sin(angle)
    zero, one = torch.zeros_like(angle), torch.ones_like(angle)
    return torch.stack([torch.stack([c, -s, zero], -1), torch.stack([s, c, zero], -1), torch.stack([zero, zero, one], -1)], -2)


def lying_peg_orientation(placement: RestingPlacement, env_idx: torch.Tensor, rng) -> torch.Tensor:
    """wxyz orientations (b, 4) of pegs lying on a random stable side, their axis (tip to head) pointing away
    from the arm within ``PEG_HEADING_JITTER``. Draws from the batched episode ``rng``: the face, then the
    heading."""
    resting = placement.face_down(env_idx, rng.uniform(0.0, 1.0))
    axis = quaternion_to_matrix(resting)[:, :, 2]
    heading = torch.as_tensor(rng.uniform(-PEG_HEADING_JITTER, PEG_HEADING_JITTER), dtype=torch.float32, device=resting.device)
    return turned_about_z(resting, heading - torch.atan2(axis[:, 1], axis[:, 0]))


def hole_in_peg_end(end: torch.Tensor, entrance: torch.Tensor, bottom: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """A hole as a peg's end sees it, given the world poses (..., 4, 4) of the end, the hole's entrance and its
    bottom: the entrance's and the bottom's positions (..., 3) and the hole's rotation (..., 3, 3) in the end's frame."""
    end_position, end_rotation = end[..., :3, 3], end[..., :3, :3]
    entrance_position, _ = relative_pose(end_position, end_rotation, entrance[..., :3, 3], entrance[..., :3, :3])
    bottom_position, hole_rotation = relative_pose(end_position, end_rotation, bottom[..., :3, 3], bottom[..., :3, :3])
    return entrance_position, bottom_position, hole_rotation
