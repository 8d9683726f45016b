"""Batched rigid-body frame maths on torch tensors (sim-free; leading batch dimension everywhere)."""

from __future__ import annotations

import torch


def rotation_6d(matrix: torch.Tensor) -> torch.Tensor:
    """The first two columns of rotation matrices (..., 3, 3), flattened row-major to (..., 6)."""
    return matrix[..., :, :2].reshape(*matrix.shape[:-2], 6)


def rotation_matrix(quaternion: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) of unit wxyz quaternions (..., 4)."""
    w, x, y, z = quaternion.unbind(-1)
    xx, yy, zz, xy, xz, yz, wx, wy, wz = x * x, y * y, z * z, x * y, x * z, y * z, w * x, w * y, w * z
    rows = (
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    )  # fmt: skip
    return torch.stack(rows, dim=-1).reshape(*quaternion.shape[:-1], 3, 3)


def relative_pose(
    parent_position: torch.Tensor, parent_rotation: torch.Tensor, child_position: torch.Tensor, child_rotation: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Position (..., 3) and rotation (..., 3, 3) of a child frame expressed in a parent frame (world inputs)."""
    inverse = parent_rotation.transpose(-1, -2)
    position = (inverse @ (child_position - parent_position).unsqueeze(-1)).squeeze(-1)
    return position, inverse @ child_rotation


def in_open_box(points: torch.Tensor, floor_centre: torch.Tensor, inner_half_size: torch.Tensor) -> torch.Tensor:
    """Whether points (n, 3) lie in an axis-aligned open box given by the centre of its floor and its inner half
    size (hx, hy, half height): within the walls and between the floor and the rim."""
    offset = points - floor_centre
    within_walls = (offset[..., :2].abs() <= inner_half_size[..., :2]).all(dim=-1)
    return within_walls & (offset[..., 2] >= 0) & (offset[..., 2] <= 2 * inner_half_size[..., 2])


def pose_matrix(position: torch.Tensor, quaternion: torch.Tensor) -> torch.Tensor:
    """Homogeneous transforms (..., 4, 4) from positions (..., 3) and wxyz quaternions (..., 4)."""
    matrix = torch.zeros(*position.shape[:-1], 4, 4, dtype=position.dtype, device=position.device)
    matrix[..., :3, :3] = rotation_matrix(quaternion)
    matrix[..., :3, 3] = position
    matrix[..., 3, 3] = 1.0
    return matrix


def angle_between(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Angle (rad) between unit vectors along the last dimension."""
    return torch.arccos(torch.clamp((a * b).sum(dim=-1), -1.0, 1.0))


def twist_error(tip_x: torch.Tensor, hole_x: torch.Tensor, axis: torch.Tensor, symmetry_order: torch.Tensor) -> torch.Tensor:
    """How far a peg is turned about the hole's axis from the nearest matching orientation, in [0, 1].

    0 when the peg's reference direction ``tip_x`` matches the hole's ``hole_x`` up to a rotation by a multiple
    of 2 pi / ``symmetry_order`` about ``axis``; 1 halfway between two matches. Order 0 means any rotation
    matches (a round peg), order 1 only the identity.
    """
    sine = (torch.cross(tip_x, hole_x, dim=-1) * axis).sum(dim=-1)
    cosine = (tip_x * hole_x).sum(dim=-1)
    angle = torch.atan2(sine, cosine) % (2 * torch.pi)
    order = symmetry_order.to(angle.dtype)
    step = 2 * torch.pi / torch.clamp(order, min=1.0)
    phase = torch.remainder(angle, step)
    error = torch.minimum(phase, step - phase) / (step / 2)
    return torch.where(order == 0, torch.zeros_like(error), error)


def insertion_measures(
    ends: torch.Tensor, valid: torch.Tensor, entrance: torch.Tensor, bottom: torch.Tensor, depth: torch.Tensor, symmetry_order: torch.Tensor
) -> dict[str, torch.Tensor]:
    """How far a peg is in a hole, per env, for the peg's insertable end nearest the entrance (``peg_end``).

    ``ends`` (n, e, 4, 4): world poses of the peg's insertable ends (z into the peg, x its reference direction);
    ``valid`` (n, e): which of them exist; ``entrance`` and ``bottom`` (n, 4, 4): the hole's frames (z out of
    the hole); ``depth`` (n,); ``symmetry_order`` (n,). The inserted fraction is 1 at the bottom and 0 at the
    entrance, measured along the hole's axis; the lateral offset is the tip's distance from that axis.
    """
    tips, tip_axes, tip_x = ends[..., :3, 3], ends[..., :3, 2], ends[..., :3, 0]
    to_entrance = torch.linalg.norm(tips - entrance[:, None, :3, 3], dim=-1).masked_fill(~valid, float("inf"))
    best = to_entrance.argmin(dim=1)
    rows = torch.arange(len(best), device=best.device)
    tip, tip_axis = tips[rows, best], tip_axes[rows, best]
    hole_axis = bottom[:, :3, 2]
    offset = tip - bottom[:, :3, 3]
    axial = (offset * hole_axis).sum(dim=-1)
    return dict(
        peg_end=best,
        lateral_offset=torch.linalg.norm(offset - axial[:, None] * hole_axis, dim=-1),
        inserted_fraction=1.0 - axial / depth,
        axis_angle=angle_between(tip_axis, hole_axis),
        twist_error=twist_error(tip_x[rows, best], bottom[:, :3, 0], hole_axis, symmetry_order),
        tip_to_entrance=to_entrance[rows, best],
        tip_to_bottom=torch.linalg.norm(offset, dim=-1),
    )



def quaternion_multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton products a * b of wxyz quaternions (..., 4)."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        (
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ),
        dim=-1,
    )


def rotation_vector(quaternion: torch.Tensor) -> torch.Tensor:
    """Axis times angle (..., 3) of unit wxyz quaternions, the short way round (angle in [0, pi])."""
    quaternion = torch.where(quaternion[..., :1] < 0, -quaternion, quaternion)
    sine = torch.linalg.norm(quaternion[..., 1:], dim=-1, keepdim=True)
    angle = 2 * torch.atan2(sine, quaternion[..., :1])
    # angle / sin(angle / 2) -> 2 as the angle -> 0
    scale = torch.where(sine > 1e-7, angle / sine.clamp_min(1e-7), torch.full_like(sine, 2.0))
    return quaternion[..., 1:] * scale


def step_velocities(
    last_position: torch.Tensor, last_quaternion: torch.Tensor, position: torch.Tensor, quaternion: torch.Tensor, dt: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean linear (..., 3) and angular (..., 3, world frame) velocity of a body that moved from one wxyz pose to
    the next in ``dt`` seconds (turning the short way round, so at most pi per step)."""
    inverse = last_quaternion * torch.tensor([1.0, -1.0, -1.0, -1.0], dtype=last_quaternion.dtype, device=last_quaternion.device)
    turn = quaternion_multiply(quaternion, inverse)
    return (position - last_position) / dt, rotation_vector(turn) / dt


def rotation_angle(rotation: torch.Tensor) -> torch.Tensor:
    """Angle (rad) of rotation matrices (..., 3, 3)."""
    trace = rotation.diagonal(dim1=-2, dim2=-1).sum(dim=-1)
    return torch.arccos(torch.clamp((trace - 1.0) / 2.0, -1.0, 1.0))


def pose_error(pose: torch.Tensor, target: torch.Tensor, half_turn_symmetric: bool = False) -> tuple[torch.Tensor, torch.Tensor]:
    """Distance (...,) and rotation angle (...,) between poses (..., 4, 4); with ``half_turn_symmetric`` the
    target may also be turned half a turn about its own z axis (an object that looks the same both ways)."""
    distance = torch.linalg.norm(pose[..., :3, 3] - target[..., :3, 3], dim=-1)
    relative = target[..., :3, :3].transpose(-1, -2) @ pose[..., :3, :3]
    angle = rotation_angle(relative)
    if half_turn_symmetric:
        half_turn = torch.diag(torch.tensor([-1.0, -1.0, 1.0], dtype=pose.dtype, device=pose.device))
        angle = torch.minimum(angle, rotation_angle(half_turn @ relative))
    return distance, angle
