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
