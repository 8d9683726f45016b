"""Whether the arm can insert a lying peg: a solvability check with the agent's own kinematic model.

``faces_the_arm_inserts`` plans with mplib, as the oracles do: the agent's description, the mount's surface and the ground
(and any other fixed obstacles the task has, e.g. the neighbouring hole modules) as obstacle points, IK from fixed
starts (deterministic) and mplib's screw motion at the insertion oracles' fine step. A resting face passes where some
grasp from above, tilted toward the peg's tip by at most ``CHECK_TILTS``' largest angle, can be reached at the lying
peg and holds the peg over its socket, from where a straight push takes it to the bottom. Steeper grasps are left out on
purpose: traced on Solar Panel Assembly's tuning seeds (see the README), the sets whose long pegs lay on faces that
only a 60-degree grasp inserts failed in every domain.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import sapien
import torch

from mani_skill_space.envs.insertion import _rotation_z
from mani_skill_space.envs.insertion import _top_grasp as top_grasp_rotation
from mani_skill_space.envs.insertion import face_checks_of, peg_placement
from mani_skill_space.procgen.asset import Asset
from mani_skill_space.procgen.cache import ArrayCache, content_key

CHECK_TILTS = np.radians([45.0, 30.0, 15.0, 0.0])
"""The grasp tilts toward the peg's tip that the check tries (the oracles' own, less their steepest, 60 degrees)."""
IK_START_COUNT = 8
MOVE_GROUP = "panda_hand_tcp"
CHECK_VERSION = "arm-reach-3"
"""Part of the cache key: change it when the check's planning changes."""


@dataclass(frozen=True)
class ArmPlanning:
    """What ``face_checks_with_the_arm`` plans with, besides the peg and its hole: the arm described by ``urdf_path``
    on ``mount``, the peg lying at ``rest_xy`` (world), and ``extra_obstacles`` (world points) besides the mount and
    the ground."""

    mount: Asset
    urdf_path: str
    rest_xy: tuple[float, float]
    extra_obstacles: Optional[np.ndarray] = None
    rest_spread: Optional[tuple[float, float, float]] = None
    """How far (m, m, rad) the episodes lay the peg from ``rest_xy`` and its heading (along x, along y, about z); the
    grasp that passes must be reachable at each corner of that range too (``faces_the_arm_inserts``)."""


def module_obstacles(hole: Asset, module: np.ndarray, peg_radius: float) -> np.ndarray:
    """Obstacle points (world) on a hole module at ``module`` (4 x 4), as the insertion oracles see it while they push
    the peg in: all but the keep-out round the hole's axis near its entrance (``oracles.insertion.outside_keepout``)."""
    from mani_skill_space.oracles.base import surface_points
    from mani_skill_space.oracles.insertion import outside_hole_keepout

    return outside_hole_keepout(surface_points(hole, module), module @ hole.frames["bottom"], float(hole.info["depth"]), peg_radius)


def face_checks_with_the_arm(
    peg: Asset,
    hole_bottom: np.ndarray,
    depth: float,
    rest_xy,
    mount: Asset,
    urdf_path: str,
    extra_obstacles: Optional[np.ndarray] = None,
    rest_spread: Optional[tuple[float, float, float]] = None,
) -> dict[str, torch.Tensor]:
    """Each solvability check's verdict (faces,) on every resting face of one peg: ``envs.insertion.face_checks_of``
    (``reachable``, ``grippable``) for an arm at ``mount``'s ``arm_mount``, and ``arm_inserts``
    (``faces_the_arm_inserts``, the same arguments, planned only for the faces that pass the others); ``insertable``:
    all of them."""
    placement = peg_placement([peg], "cpu")
    checks = face_checks_of(peg, hole_bottom, mount.frames["arm_mount"][:3, 3], placement)
    candidates = checks["insertable"].numpy()
    arm = np.zeros_like(candidates)
    if candidates.any():
        faces = placement.rotations().double().numpy()[candidates]
        arm[candidates] = faces_the_arm_inserts(peg, faces, rest_xy, hole_bottom, depth, urdf_path, mount, extra_obstacles, rest_spread)
    checks["arm_inserts"] = torch.as_tensor(arm)
    checks["insertable"] = checks["insertable"] & checks["arm_inserts"]
    return checks


def faces_the_arm_inserts(
    peg: Asset,
    faces: np.ndarray,
    rest_xy,
    hole_bottom: np.ndarray,
    depth: float,
    urdf_path: str,
    mount: Asset,
    extra_obstacles: Optional[np.ndarray] = None,
    rest_spread: Optional[tuple[float, float, float]] = None,
) -> np.ndarray:
    """(F,) bool: which of the peg's resting ``faces`` (F, 3, 3: peg to world, lying on each) let the arm insert it
    (see the module), the peg lying at ``rest_xy`` (world) with its tip toward the arm, its socket's bottom frame
    ``hole_bottom`` (world, 4 x 4, z out of the socket) ``depth`` deep, for the arm described by ``urdf_path`` on
    ``mount`` (at its ``arm_mount`` frame), with ``extra_obstacles`` (world points) besides the mount and the
    ground. Given ``rest_spread`` (m, m, rad: how far the episodes lay the peg from ``rest_xy`` along x and y, and
    turn it from pointing straight away), the grasp must also be reachable with the peg lying at each corner of that
    range: a grasp that only reaches the peg where it lies on average leaves the episodes that lay it elsewhere
    unsolvable (Multi-Peg-in-Hole, tuning seed 62006: the only grasp whose push works could not be reached with the
    peg 2 cm off its lane). The verdicts are cached on disk (``procgen.cache``): planning takes tens of milliseconds
    a face."""
    obstacles = planning_obstacle_points(mount, extra_obstacles)
    inputs = [np.asarray(a, dtype=np.float64) for a in (peg.collision_vertices, peg.frames["end_0"], faces, rest_xy, hole_bottom, [depth, peg.info["height"], peg.info["symmetry_order"]])]
    if rest_spread is not None:
        inputs.append(np.asarray(rest_spread, dtype=np.float64))
    key = content_key(CHECK_VERSION, _description_key(urdf_path), obstacles.tobytes(), mount.frames["arm_mount"].tobytes(), *(a.tobytes() for a in inputs))

    def build() -> dict[str, np.ndarray]:
        from mani_skill_space.oracles.insertion import _twists

        planner = _planner_for(urdf_path, obstacles.tobytes())
        to_base = np.linalg.inv(mount.frames["arm_mount"])
        twists = _twists(int(peg.info["symmetry_order"]))
        verdicts = [_face_inserts(planner, to_base, peg, rest, rest_xy, hole_bottom, depth, twists, rest_spread) for rest in faces]
        return {"inserts": np.array(verdicts, dtype=bool)}

    return ArrayCache("arm_reach").get_or_create(key, build)["inserts"]


def _face_inserts(
    planner, to_base, peg: Asset, rest: np.ndarray, rest_xy, hole_bottom, depth: float, twists: np.ndarray, rest_spread: Optional[tuple[float, float, float]] = None
) -> bool:
    """The oracles' grasp (``oracles.insertion``: finger pads clear of the socket, at the peg's middle if that is
    farther from the tip, clear of its head) and approach (the tip ``APPROACH_GAP`` over the socket's entrance); the
    grasp reachable at every corner of ``rest_spread`` too, where given (the push does not depend on where the peg
    lay: the hand holds it the same way)."""
    from mani_skill_space.oracles.insertion import APPROACH_GAP, FINGER_MARGIN, HEAD_OVERHANG, PAD_REACH, _along_axis

    tip = _lying_tip(peg, rest, rest_xy)
    elsewhere = [_lying_tip(peg, rest, (rest_xy[0] + dx, rest_xy[1] + dy), heading) for dx, dy, heading in _corners(rest_spread)]
    height = float(peg.info["height"])
    reach = min(max(depth + PAD_REACH + FINGER_MARGIN, height / 2), height - HEAD_OVERHANG)

    def grasp_at(lying_tip: np.ndarray, tilt: float, wrist: float) -> np.ndarray:
        return _along_axis(_top_grasp(lying_tip, tilt, reach), wrist, 0.0)

    def reachable(lying_tip: np.ndarray, tilt: float, wrist: float) -> bool:
        return _ik(planner, to_base @ grasp_at(lying_tip, tilt, wrist)) is not None

    for tilt in CHECK_TILTS:
        for wrist in (0.0, np.pi):
            grasp = grasp_at(tip, tilt, wrist)
            if _ik(planner, to_base @ grasp) is None:
                continue
            hand_from_tip = np.linalg.inv(np.linalg.inv(grasp) @ tip)
            # the corners first: on 100 multi-peg pairs they cost less than the pushes and fail more often
            if all(reachable(other, tilt, wrist) for other in elsewhere) and _pushes_in(planner, to_base, hand_from_tip, hole_bottom, depth + APPROACH_GAP, twists):
                return True
    return False


def _pushes_in(planner, to_base, hand_from_tip: np.ndarray, hole_bottom: np.ndarray, approach_height: float, twists: np.ndarray) -> bool:
    """Whether, at some twist, the hand holding the tip (``hand_from_tip``) ``approach_height`` over the socket's
    bottom on its axis can push it straight to the bottom."""
    from mani_skill_space.oracles.insertion import _along_axis

    for twist in twists:
        pressed = to_base @ _along_axis(hole_bottom, twist, 0.0) @ hand_from_tip
        for over in _ik_solutions(planner, to_base @ _along_axis(hole_bottom, twist, approach_height) @ hand_from_tip):
            if _screw_reaches(planner, over, pressed):
                return True
    return False


def _corners(rest_spread: Optional[tuple[float, float, float]]) -> list[tuple[float, float, float]]:
    """The corners (dx, dy, heading) of the range ``rest_spread`` (half-widths), or none."""
    if rest_spread is None:
        return []
    return [(sx * rest_spread[0], sy * rest_spread[1], sh * rest_spread[2]) for sx in (-1, 1) for sy in (-1, 1) for sh in (-1, 1)]


def _lying_tip(peg: Asset, rest: np.ndarray, rest_xy, heading: float = 0.0) -> np.ndarray:
    """The insertable end's world frame with the peg lying on ``rest`` at ``rest_xy``, its axis (tip to head) turned
    to point away from the arm (+x), then by ``heading`` about z, its lowest point on the ground."""
    tip_in_peg = peg.frames["end_0"]
    axis = rest @ tip_in_peg[:3, 2]
    lying = _rotation_z(torch.tensor(heading - np.arctan2(axis[1], axis[0]), dtype=torch.float64)).numpy() @ rest
    tip = np.eye(4)
    tip[:3, :3] = lying @ tip_in_peg[:3, :3]
    tip[:3, 3] = lying @ tip_in_peg[:3, 3] + [rest_xy[0], rest_xy[1], -(peg.collision_vertices @ lying.T)[:, 2].min()]
    return tip


def _top_grasp(tip: np.ndarray, tilt: float, reach: float) -> np.ndarray:
    """The hand (x, closing, approach columns) taking the lying peg from above, tilted by ``tilt`` toward its tip,
    ``reach`` from the tip along its axis (``envs.insertion``'s grasp, as the oracles take it unrolled)."""
    hand = np.eye(4)
    hand[:3, :3] = top_grasp_rotation(torch.as_tensor(tip[:3, 2], dtype=torch.float64), float(tilt)).numpy()
    hand[:3, 3] = tip[:3, 3] + reach * tip[:3, 2]
    return hand


def _pose_vector(pose: np.ndarray) -> np.ndarray:
    p = sapien.Pose(pose)
    return np.concatenate([p.p, p.q])


def _ik(planner, pose_in_base: np.ndarray):
    """A collision-free IK solution (arm joints) for the TCP at ``pose_in_base``, from fixed starts; None if none."""
    return next(_ik_solutions(planner, pose_in_base), None)


def _ik_solutions(planner, pose_in_base: np.ndarray):
    """Collision-free IK solutions for the TCP at ``pose_in_base``, one per fixed start that finds one, lazily."""
    goal = _pose_vector(pose_in_base)
    for start in _ik_starts(planner):
        status, found = planner.IK(goal, planner.pad_qpos(start.copy()), n_init_qpos=1)
        if status == "Success":
            yield found[0]


def _screw_reaches(planner, qpos: np.ndarray, pose_in_base: np.ndarray) -> bool:
    """Whether mplib's screw motion, at the insertion oracles' joint step (``oracles.base.FINE_SCREW_STEP``: at a
    coarser step it drifts off the straight line and can step over a thin shell of obstacle points), takes the TCP
    from ``qpos`` to ``pose_in_base`` without touching the obstacles."""
    from mani_skill_space.oracles.base import FINE_SCREW_STEP

    return screw_path_is_free(planner, qpos, _pose_vector(pose_in_base), FINE_SCREW_STEP)


def screw_path_is_free(planner, qpos: np.ndarray, target_pose: np.ndarray, qpos_step: float) -> bool:
    """``planner.plan_screw(target_pose, qpos, qpos_step, use_point_cloud=True)["status"] == "Success"`` (mplib
    0.1), without the path's time parameterisation: the same steps along the screw from ``qpos`` to
    ``target_pose`` ([x, y, z, qw, qx, qy, qz], the planner's world frame), each checked against the joint limits
    and the obstacles, but no TOPP-RA (a third of ``plan_screw``'s time, and it cannot fail a path mplib found
    free). A solvability check needs only the verdict; ``tests/envs/test_reachable_placements.py`` checks that it is
    mplib's."""
    planner.planning_world.set_use_point_cloud(True)
    planner.planning_world.set_use_attach(False)
    qpos = planner.pad_qpos(np.array(qpos, dtype=np.float64))
    planner.robot.set_qpos(qpos, True)
    target = _pose_matrix(planner.transform_goal_to_wrt_base(np.asarray(target_pose, dtype=np.float64)))
    model = planner.pinocchio_model
    model.compute_forward_kinematics(qpos)
    tcp = planner.link_name_2_idx[planner.move_group]
    twist = _screw_coordinates(target @ np.linalg.inv(_pose_matrix(model.get_link_pose(tcp))))
    if twist is None:
        return False
    joints = planner.move_group_joint_indices
    limits = np.asarray(planner.joint_limits)
    while True:
        model.compute_full_jacobian(qpos)
        jacobian = model.get_link_jacobian(tcp, local=False)
        delta_q = np.linalg.pinv(jacobian) @ twist
        delta_q *= qpos_step / np.linalg.norm(delta_q)
        delta_twist = jacobian @ delta_q
        last = np.linalg.norm(delta_twist) > np.linalg.norm(twist)
        if last:
            ratio = np.linalg.norm(twist) / np.linalg.norm(delta_twist)
            delta_q, delta_twist = delta_q * ratio, delta_twist * ratio
        qpos += delta_q.reshape(-1)
        twist -= delta_twist
        within_limits = bool(np.all((qpos >= limits[:, 0] - 1e-3) & (qpos <= limits[:, 1] + 1e-3)))
        planner.planning_world.set_qpos_all(qpos[joints])
        if np.linalg.norm(delta_twist) < 1e-4 or planner.planning_world.collide() or not within_limits:
            return False
        if last:
            return True


def _pose_matrix(pose: np.ndarray) -> np.ndarray:
    from transforms3d.quaternions import quat2mat

    matrix = np.eye(4)
    matrix[:3, 3] = pose[:3]
    matrix[:3, :3] = quat2mat(pose[3:])
    return matrix


def _screw_coordinates(relative: np.ndarray) -> Optional[np.ndarray]:
    """(6, 1): the twist (v, omega) times its angle that takes a pose to ``relative`` times it, as mplib's
    ``plan_screw`` computes it (its ``pose2exp_coordinate``); None for a half turn, where mplib gives up."""
    trace = relative[:3, :3].trace()
    if np.isclose(trace, 3):
        omega, theta = np.zeros(3), 1
    elif np.isclose(trace, -1):
        return None
    else:
        rotation = relative[:3, :3]
        theta = np.arccos((trace - 1) / 2)
        omega = 1 / 2 / np.sin(theta) * np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]])
    skew = np.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]], [-omega[1], omega[0], 0]])
    inverse_left_jacobian = np.eye(3) / theta - 0.5 * skew + (1.0 / theta - 0.5 / np.tan(theta / 2)) * skew @ skew
    return (np.concatenate([inverse_left_jacobian @ relative[:3, 3], omega]) * theta).reshape(-1, 1)


def _ik_starts(planner) -> np.ndarray:
    """The arm's rest pose, then the oracles' fixed pseudo-random starts (the same in every process)."""
    from mani_skill_space.oracles.base import _ik_starts as random_starts

    rest = np.array([0.0, np.pi / 8, 0.0, -5 * np.pi / 8, 0.0, 3 * np.pi / 4, np.pi / 4])
    return np.concatenate([rest[None], random_starts(planner, 7, IK_START_COUNT)])


@functools.lru_cache(maxsize=4)
def _description_key(urdf_path: str) -> str:
    """The robot description's content hash (read once per process, not once per peg)."""
    return content_key(Path(urdf_path).read_bytes())


@functools.lru_cache(maxsize=8)
def _planner_for(urdf_path: str, obstacle_points: bytes):
    """mplib's planner for the arm in its base frame, with ``obstacle_points`` (base frame)."""
    import mplib

    planner = mplib.Planner(urdf=urdf_path, srdf=str(Path(urdf_path).with_suffix(".srdf")), move_group=MOVE_GROUP)
    planner.update_point_cloud(np.frombuffer(obstacle_points).reshape(-1, 3))
    # IK checks the points only once this is set, and plan_screw sets it: set from the start, so that every IK
    # solution is collision-free (as the oracles' are) and no verdict depends on what the planner did before
    planner.planning_world.set_use_point_cloud(True)
    return planner


def planning_obstacle_points(mount: Asset, extra_obstacles: Optional[np.ndarray] = None) -> np.ndarray:
    """The points the check plans around, in the arm's base frame: what the arm stands on (``_obstacle_points``) and
    ``extra_obstacles`` (world points)."""
    obstacles = _obstacle_points(mount)
    if extra_obstacles is None:
        return obstacles
    return np.ascontiguousarray(np.concatenate([obstacles, np.asarray(extra_obstacles, dtype=np.float64) - mount.frames["arm_mount"][:3, 3]]))


def _obstacle_points(mount: Asset) -> np.ndarray:
    """The oracles' obstacle points of what the arm stands on (``oracles.base.standing_obstacle_points``, as
    ``Oracle.make_solver`` takes them) in the arm's base frame."""
    shape = content_key(mount.frames["arm_mount"].tobytes(), *(np.ascontiguousarray(part.mesh.vertices).tobytes() for part in mount.collision_parts))
    return _obstacle_points_of(shape, mount)


_OBSTACLE_POINTS: dict[str, np.ndarray] = {}


def _obstacle_points_of(shape: str, mount: Asset) -> np.ndarray:
    if shape not in _OBSTACLE_POINTS:
        from mani_skill_space.oracles.base import standing_obstacle_points

        points = standing_obstacle_points(mount) - mount.frames["arm_mount"][:3, 3]
        _OBSTACLE_POINTS[shape] = np.ascontiguousarray(points, dtype=np.float64)
    return _OBSTACLE_POINTS[shape]
