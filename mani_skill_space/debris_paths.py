"""Where a drifting piece of debris can be caught: its ballistic path against the arm's reach (sim-free, batched).

Debris Capture draws each episode's start (position, drift, tumble) and keeps only a path that a Panda can meet:
the debris must stay within the arm's reach, above the surface the arm stands on, long enough after the arm has
had time to bring its open hand there and before it strikes the base camera's post (``seconds_within_reach``). The
oracle searches the same shell for its meeting point (``oracles.debris_capture``).
"""

from __future__ import annotations

import numpy as np
import torch

from mani_skill_space.procgen.mounts import ARM_MOUNT_HEIGHT, BASE_CAMERA_POST_TOP, BASE_CAMERA_POST_XY

SHOULDER_HEIGHT = 0.333
"""Height of the Panda's shoulder joint above its base."""
REACH = (0.4, 0.8)
"""Distances (m) from the shoulder at which the hand can meet the debris and still move back with it."""
LOWEST_MEETING_HEIGHT = 0.12
"""Meet the debris at least this high above the platform or ground (room for the hand below it)."""
HAND_READY_TIME = 1.5
"""Seconds the arm needs to bring its open hand from where it starts to a meeting point and be waiting there (its
joint-space move there takes 0.5-1 s, and it should be in place 0.6 s before the debris arrives)."""
MIN_SECONDS_WITHIN_REACH = 1.5
"""A start is kept only if its path stays this long within the arm's reach after ``HAND_READY_TIME``. Measured with
the oracle on seeds 61000-61039 (orbit and asteroid, both asset sources) before the check: of the 16 starts below it
(all on the asteroid) 3 were caught, and 12 of the other 13 were paths the hand could meet nowhere in time; of those
above it, 64% (the rest were captures lost as the fingers closed)."""
LATEST_MEETING = 8.0
"""Seconds into the episode by which the hand must meet the debris: holding it calm for 0.5 s after the fingers
close and brake needs most of the rest of the 10 s episode."""
CANDIDATE_STARTS = 8
"""Starts drawn per episode; the first that passes is kept (7 of 40 asteroid episodes and none of 40 in orbit needed
a second one, seeds 61000-61039)."""
POST_CLEARANCE = 0.06
"""m: a path whose centre comes this close (horizontally, below the top of its head) to the axis of the base camera's
post on the station or rover strikes it. On the dataset debris' tuning and suite seeds (orbit and asteroid, 340
episodes) the oracle found no meeting for 4 starts that passed the reach check; all four flew into the post (their
centres 8-52 mm from its axis), which stands in front of the arm's base, where the hand's late meetings would be."""
TIME_STEP = 0.05


def seconds_within_reach(
    position: torch.Tensor, velocity: torch.Tensor, gravity: torch.Tensor, shoulder: torch.Tensor, horizon: float = LATEST_MEETING, camera_post: bool = True
) -> torch.Tensor:
    """Seconds (...) that the ballistic path from ``position`` with ``velocity`` (..., 3) under ``gravity`` (3,)
    spends within ``REACH`` of ``shoulder`` (..., 3, broadcast) and at least ``LOWEST_MEETING_HEIGHT`` above the
    surface the arm stands on (``shoulder`` minus the shoulder's and the arm base's height above it), between
    ``HAND_READY_TIME`` and ``horizon`` seconds from now; where the arm stands on a mount with the base camera's post
    in front of it (``camera_post``; not the free-flying servicer), only until the path strikes the post
    (``POST_CLEARANCE``)."""
    times = torch.arange(HAND_READY_TIME, horizon, TIME_STEP, dtype=position.dtype, device=position.device)
    t = times.reshape(-1, *([1] * position.dim()))  # (T, ..., 1)
    points = position + velocity * t + 0.5 * gravity * t * t  # (T, ..., 3)
    distance = torch.linalg.norm(points - shoulder, dim=-1)
    surface = shoulder[..., 2] - SHOULDER_HEIGHT - ARM_MOUNT_HEIGHT
    inside = (distance >= REACH[0]) & (distance <= REACH[1]) & (points[..., 2] >= surface + LOWEST_MEETING_HEIGHT)
    if camera_post:
        inside &= t[..., 0] < seconds_to_camera_post(position, velocity, gravity, shoulder - shoulder.new_tensor([0.0, 0.0, SHOULDER_HEIGHT]), horizon)
    return inside.sum(dim=0).to(position.dtype) * TIME_STEP


def seconds_to_camera_post(position: torch.Tensor, velocity: torch.Tensor, gravity: torch.Tensor, base: torch.Tensor, horizon: float = LATEST_MEETING) -> torch.Tensor:
    """Seconds (...) until the ballistic path from ``position`` with ``velocity`` (..., 3) under ``gravity`` (3,)
    strikes the base camera's post in front of the arm's base at ``base`` (..., 3, broadcast): its centre within
    ``POST_CLEARANCE`` of the post's axis, no higher than that above the camera's head; infinity where it does not
    within ``horizon``."""
    times = torch.arange(0.0, horizon, TIME_STEP, dtype=position.dtype, device=position.device)
    t = times.reshape(-1, *([1] * position.dim()))
    points = position + velocity * t + 0.5 * gravity * t * t  # (T, ..., 3)
    post = base[..., :2] + base.new_tensor(BASE_CAMERA_POST_XY)
    at_post = (torch.linalg.norm(points[..., :2] - post, dim=-1) < POST_CLEARANCE) & (points[..., 2] <= base[..., 2] + BASE_CAMERA_POST_TOP + POST_CLEARANCE)
    first = torch.where(at_post, t[..., 0], torch.full_like(at_post, float("inf"), dtype=position.dtype))
    return first.min(dim=0).values


def first_catchable(seconds: torch.Tensor) -> torch.Tensor:
    """Index (...) along the last axis of ``seconds`` (..., K): the first of K candidate starts whose path stays at
    least ``MIN_SECONDS_WITHIN_REACH`` within reach, or, where none does, the one that stays longest."""
    catchable = seconds >= MIN_SECONDS_WITHIN_REACH
    first = catchable.int().argmax(dim=-1)
    return torch.where(catchable.any(dim=-1), first, seconds.argmax(dim=-1))


def tumbling_rotations(rotation: np.ndarray, angular_velocity: np.ndarray, principal_inertia: np.ndarray, principal_axes: np.ndarray, times: np.ndarray, step: float = 0.005) -> np.ndarray:
    """World rotations (T, 3, 3) at ``times`` (T,, seconds from now, ascending) of a free rigid body (no torque)
    that now has ``rotation`` (3, 3, body to world) and world ``angular_velocity`` (3,), with ``principal_inertia``
    (3,) about ``principal_axes`` (3, 3, columns, in the body frame): Euler's equations integrated (RK4 on the
    principal-frame angular velocity, the exact rotation for each step's mean angular velocity). A body that does
    not spin about a principal axis does not keep its angular velocity: its axes precess about its constant angular
    momentum, which a prediction at constant angular velocity misses by a quarter turn within a second or two."""
    inertia = np.asarray(principal_inertia, dtype=np.float64)
    frame = np.asarray(rotation, dtype=np.float64) @ np.asarray(principal_axes, dtype=np.float64)  # principal frame to world
    omega = frame.T @ np.asarray(angular_velocity, dtype=np.float64)  # in the principal frame

    def euler(w: np.ndarray) -> np.ndarray:
        return np.array([(inertia[1] - inertia[2]) * w[1] * w[2], (inertia[2] - inertia[0]) * w[2] * w[0], (inertia[0] - inertia[1]) * w[0] * w[1]]) / inertia

    out, now = [], 0.0
    for target in np.asarray(times, dtype=np.float64):
        while now < target - 1e-12:
            h = min(step, target - now)
            k1 = euler(omega)
            k2 = euler(omega + h / 2 * k1)
            k3 = euler(omega + h / 2 * k2)
            k4 = euler(omega + h * k3)
            new_omega = omega + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            frame = frame @ _axis_angle_matrix((omega + new_omega) / 2 * h)
            omega, now = new_omega, now + h
        out.append(frame @ np.asarray(principal_axes, dtype=np.float64).T)  # back to body to world
    return np.stack(out)


def _axis_angle_matrix(rotation_vector: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(rotation_vector))
    if angle < 1e-12:
        return np.eye(3)
    k = rotation_vector / angle
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * cross + (1 - np.cos(angle)) * cross @ cross
