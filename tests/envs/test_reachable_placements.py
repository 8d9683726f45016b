"""Procedural Peg-in-Hole instances are reachable by construction: a peg lies only on faces from which the arm can
hold it over its hole (``envs.insertion.reachable_faces``), and a pair with no such face is drawn again."""

import numpy as np
import pytest
import torch

from mani_skill_space.envs.insertion import peg_placement, reachable_faces
from mani_skill_space.envs.peg_in_hole_assembly import MODULE_POSITION, reachable_peg_hole_pair
from mani_skill_space.procgen.mounts import make_rover
from mani_skill_space.procgen.peg_hole import make_peg_hole_pair

ARM_BASE = torch.as_tensor(make_rover().frames["arm_mount"][:3, 3], dtype=torch.float32)


def _twisted(frame: np.ndarray, angle: float) -> np.ndarray:
    """``frame`` turned by ``angle`` about its own z axis."""
    c, s = np.cos(angle), np.sin(angle)
    turn = np.eye(4)
    turn[:2, :2] = [[c, -s], [s, c]]
    return frame @ turn


def _faces(pegs, bottoms, symmetry):
    as_tensor = lambda x: torch.as_tensor(np.asarray(x), dtype=torch.float32)  # noqa: E731
    return reachable_faces(peg_placement(pegs, "cpu"), as_tensor([p.frames["end_0"] for p in pegs]), as_tensor(bottoms), torch.as_tensor(symmetry), ARM_BASE)


def _world_bottom(hole) -> np.ndarray:
    module = np.eye(4)
    module[:3, 3] = MODULE_POSITION
    return module @ hole.frames["bottom"]


def test_a_hole_that_only_fits_with_the_hand_pointing_back_at_the_arm_is_unreachable():
    peg, hole = make_peg_hole_pair(7)
    upright = np.eye(4)
    upright[:3, 3] = _world_bottom(hole)[:3, 3]
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    # one allowed twist (symmetry 1): twisting the hole about its axis turns the hand with it, and lying on a
    # given face the peg is reachable for some twists only
    first_face = np.array([bool(_faces([peg], [_twisted(upright, angle)], [1])[0, 0]) for angle in angles])
    assert first_face.any() and not first_face.all()
    # a round peg fits at any twist: every face always reachable
    for angle in angles:
        faces = _faces([peg], [_twisted(upright, angle)], [0])
        assert bool(faces.all())


def test_reachable_faces_is_batched_and_leaves_out_padded_faces():
    pairs = [make_peg_hole_pair(seed) for seed in range(8)]
    pegs = [p for p, _ in pairs]
    faces = _faces(pegs, [_world_bottom(h) for _, h in pairs], [p.info["symmetry_order"] for p in pegs])
    placement = peg_placement(pegs, "cpu")
    assert faces.shape == placement.allowed.shape == (8, placement.quaternions.shape[1])
    assert not bool((faces & ~placement.allowed).any())
    for i, peg in enumerate(pegs):  # the same as each env alone
        alone = _faces([peg], [_world_bottom(pairs[i][1])], [peg.info["symmetry_order"]])[0]
        assert torch.equal(faces[i, : len(alone)], alone) and not bool(faces[i, len(alone) :].any())


def test_face_down_picks_only_allowed_faces_deterministically():
    pegs = [make_peg_hole_pair(seed)[0] for seed in range(8)]
    placement = peg_placement(pegs, "cpu")
    several = placement.counts >= 2
    assert bool(several.any())
    allowed = placement.allowed.clone()
    allowed[several, 0] = False  # leave out the first face of each peg that has another
    placement.allow_only(allowed)
    env_idx = torch.arange(8)
    for uniform in np.linspace(0.0, 0.999, 7):
        chosen = placement.face_down(env_idx, np.full(8, uniform))
        first = torch.isclose(chosen, placement.quaternions[:, 0]).all(dim=1)
        assert not bool(first[several].any())
        assert torch.equal(chosen, placement.face_down(env_idx, np.full(8, uniform)))
    with pytest.raises(ValueError, match="at least one"):
        placement.allow_only(torch.zeros_like(allowed))


def test_every_procedural_pair_has_a_reachable_face_and_records_its_check():
    arm = ARM_BASE.numpy()
    for seed in range(40):
        peg, hole = reachable_peg_hole_pair(seed, 0.001, arm)
        record = hole.info["feasibility"]
        assert record["reachable_resting_faces"] >= 1 and record["draws"] >= 1
        faces = _faces([peg], [_world_bottom(hole)], [peg.info["symmetry_order"]])
        assert int(faces.sum()) == record["reachable_resting_faces"]
        if record["draws"] == 1:
            assert peg.name == make_peg_hole_pair(seed)[0].name  # a pair that passes is the seed's own


def test_every_procedural_solar_set_has_a_reachable_face_for_each_peg():
    from mani_skill_space.envs.solar_panel_assembly import PANEL_TARGET_XY, reachable_solar_set
    from mani_skill_space.envs.insertion import reachable_faces_of
    from mani_skill_space.procgen.solar_panel import socket_frames

    origin = np.eye(4)
    origin[:2, 3] = PANEL_TARGET_XY
    for seed in range(10):
        layout, pegs = reachable_solar_set(seed, 0.001, ARM_BASE.numpy())
        record = pegs[0].info["feasibility"]
        frames = socket_frames(layout)
        counts = [int(reachable_faces_of(peg, origin @ frames[f"bottom_{i}"], ARM_BASE.numpy()).sum()) for i, peg in enumerate(pegs)]
        assert counts == record["reachable_resting_faces"] and min(counts) >= 1
