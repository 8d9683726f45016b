"""Oracle for DebrisCapture-v1: predict the debris' ballistic path and put the open hand on it ahead of the
debris, fingers facing it, by an arm motion that keeps every link out of the debris' way until it reaches the
hand; as it comes close, move the hand with it (so the fingers close on an object at
rest relative to them), close, keep moving with it while braking gently to a stop, and hold still. Debris that gets
away (bounces off the hand or the arm, slips from fingers that closed on its rim, or slips out of them as the hand
brakes) is chased, the fingers open; where it comes to rest on the ground or on the mount's deck instead, it is taken
from above."""

from __future__ import annotations

from contextlib import contextmanager
from typing import Callable, Generator, Iterator, Optional

import numpy as np
import sapien
import torch
from mplib.pymp.collision_detection import fcl

from mani_skill_space.debris_paths import LATEST_MEETING, LOWEST_MEETING_HEIGHT, REACH, SHOULDER_HEIGHT, tumbling_rotations
from mani_skill_space.oracles.base import (
    GRIPPER_CLOSED,
    GRIPPER_OPEN,
    JOINT_ACCELERATION_LIMIT,
    Oracle,
    PlanningFailed,
    collision_part_vertices,
    finger_box_corners,
    finger_pad_rectangle,
    pad_overlap,
    raised,
    tcp_pose_with_axes,
    top_down_grasp_pose,
)
from mani_skill_space.oracles.sample_collection import PRE_GRASP_HEIGHT
from mani_skill_space.procgen.polytope import clip

EARLIEST_MEETING = 0.8
TIME_STEP = 0.1
ARRIVAL_MARGIN = 0.6
"""Seconds the hand should be in place before the debris arrives."""
FOLLOW_DISTANCE = 0.06
"""Once the debris' centre is this close (m) to the hand, the hand moves with it..."""
FOLLOW_REACH_MARGIN = 0.02
"""...or, for a larger body, once its centre is within its radius (``_debris_radius``) and this (m) of the hand: a
tumbling body's far end reaches the hand before its centre comes within ``FOLLOW_DISTANCE``, and struck by the hand
standing still, a 200 mm peg or a 3U CubeSat drifted off out of the fingers' reach (on the dataset's orbital tuning seeds
3000-3399, 43 of 400 were lost, nearly all of them got away; moving with them from here, 35 were lost)."""
SWEEP_TIME_STEP = 0.1
HAND_LENGTH = 0.12
"""Debris farther than its radius plus this (m) from the grasp point cannot touch the hand waiting there."""
TILTS = tuple(np.radians([0.0, 30.0, 60.0]))
ALONG_THE_FINGERS = -1.0
"""For a long body, first: the hand turned so that the body will lie along the finger pads' width, across both the
closing and the approach (``_along_the_fingers``), so that it neither strikes the palm end first nor lies across
the fingers' gap."""
"""Grasp orientations tried at each meeting point: fingers against the debris' velocity, then tilted toward
pointing down."""
ACROSS_THE_THIN_SIDE = -2.0
"""For a body that is not long and turns no faster than ``THIN_SIDE_MOST_SPIN``, last, where it fits between the open
fingers: the fingers closing across its thinnest side (``_across_the_thin_side``), so that a flat body wider than the
fingers are deep (a panel, a plate), which comes flat against the fingers or the palm whatever way the usual grasps
close, comes in edge first between the pads until that edge meets the palm, and is held by it."""
THIN_SIDE_MOST_SPIN = 0.5
"""rad/s: a flat body turning faster swings its edge out from between the pads before they close (met so at difficulty 1,
5 more of the first 163 procedural orbital tuning seeds were lost, and none gained)."""
FIT_WINDOW = 2
"""A meeting is first sought where the body will fit the open hand (``_fits_the_open_hand``) as it turns from this many
``TIME_STEP``s before it is due there to as many after (its arrival is not timed exactly); a body tumbling fast fits
nowhere throughout, and is met where the hand can be in time."""
MOST_FOLLOW_STEPS = 40
CHASE_LEAD = 0.15
"""Seconds (a control step and the Panda's drives' 0.1 s lag) ahead of the hand that the chase puts its target, so that
the hand moves as fast as it is asked to (a target one step ahead of a hand that lags two moves it at half that)."""
RESERVED_STEPS = 30
"""Control steps the chase leaves at the end of the episode for the fingers to close, the brake and the calm hold."""
CHASE_CATCH_SPEED = 0.15
"""How fast (m/s) the chase closes in on the debris: a debris that got away moves off rather than into the hand, so the
chase must close faster than the follow (``CATCH_SPEED``) to reach it before it leaves the arm's reach."""
STUCK_CHASE_STEPS = 5
"""Control steps in a row the chase holds the arm still for want of an IK solution near its joints (the wrist at its
limit, or the nearest solution on another branch) before it steps toward a farther one: in every orbital failure
traced on the dataset's tuning seeds the chase stood still like this for 68-122 steps, in some while the debris drifted
off slowly within reach."""
CLOSED_FOLLOW_STEPS = 6
CATCH_SPEED = 0.08
"""How fast (m/s) the debris may close in on the hand while the hand moves with it."""
CATCH_TIME = 0.15
CLOSE_RADIUS = 0.012
"""The fingers close once the debris' centre is this close (m) to the grasp point..."""
CLOSE_PAD_OVERLAP = 0.35
"""...or once it touches the hand with its parts between the open fingers covering this share of the finger pads
(``base.pad_overlap``): a long body's centre may never come between them. (Closing as soon as anything touched the
hand closed the fingers on nothing when a satellite's wing or antenna brushed a fingertip first; closing as soon
as the pads would meet something, before it touched, closed them on its leading edge.)"""
BROADSIDE_COSINE = 0.5
"""A long body is first sought where its long axis makes at least 60 degrees with its path (it lies across it)."""
ELONGATED_RATIO = 1.5
"""A body whose longest side is this many times its middle one is long (the 3U CubeSat, the 200 mm peg)."""
OPEN_FINGER_GAP = 0.04
"""Half the gap (m) between the open fingers' pads."""
BRAKE_STEPS = 12
HOLD_STEPS = 60
PANDA_LOWEST_JOINT_ACCELERATION = 7.5
"""rad/s^2: the lowest of the Panda's own joint acceleration limits (7.5-20 rad/s^2, joint 2's)."""
FAST_SWING = PANDA_LOWEST_JOINT_ACCELERATION / JOINT_ACCELERATION_LIMIT
"""Acceleration scale (1.875) of the swing to a meeting that the usual swing cannot reach in time: every joint at the
Panda's lowest joint acceleration limit instead of the oracles' usual ``base.JOINT_ACCELERATION_LIMIT``."""


RESTING_SPEED = 0.03
"""m/s: debris touching the ground or the mount this slowly has come to rest there (the asteroid's weak gravity brings
down debris that got away below the hand, often within reach of the rover's arm; in orbit, debris struck down onto the
station's deck may stay there)."""


DEBRIS_BALL = "debris_ball"
"""The planner's collision object standing for the ball the tumbling debris sweeps (``_clear_of_debris``)."""
DEBRIS_AT_REST = "debris_at_rest"
"""The planner's collision object standing for debris at rest on the ground (``_debris_as_obstacle``)."""


class DebrisCaptureOracle(Oracle):
    def plan(self, env) -> Iterator[np.ndarray]:
        self.make_solver(env)
        meeting, arm = self._meeting_point(env)
        yield from self.joint_move(arm, "meeting", acceleration=self.swing_acceleration)
        arrived = yield from self._wait_for_debris(env, meeting)
        self._grip_orientation = meeting.q
        yield from self._follow_debris(env, meeting, arrived)
        yield from self._brake(env)
        while not self._holding(env) and self._time_left(env):  # it slipped out of the fingers as they braked: chase it again
            yield from self._follow_debris(env, meeting, arrived=False)
            yield from self._brake(env)
        yield from self.wait_for_success(HOLD_STEPS)

    def _follow_debris(self, env, meeting: sapien.Pose, arrived: bool) -> Iterator[np.ndarray]:
        """Where the debris ``arrived`` at the hand, move with it until the fingers have closed on it (for a few steps)
        or ``MOST_FOLLOW_STEPS`` have passed. Where they do not hold it then (the debris struck the hand and bounced off
        slower, and the hand, moving with it from where its drives left it, fell behind; or the fingers closed on the
        rim of a tumbling body that swept on), or where it never arrived (it struck the arm and drifted off before it
        came to the hand), chase it: the same motion with the target ``CHASE_LEAD`` ahead of the hand, which makes up
        the drives' lag, closing in at ``CHASE_CATCH_SPEED``, with the fingers opened again, until they hold it or
        only ``RESERVED_STEPS`` are left."""
        if arrived:
            yield from self._until_held(lambda step: self._on_debris(env, meeting), "follow", lambda step: step < MOST_FOLLOW_STEPS)
        chase = lambda step: self._on_debris(env, meeting, lead=CHASE_LEAD, catch_speed=CHASE_CATCH_SPEED)  # noqa: E731
        while not self._holding(env) and self._time_left(env):
            self.gripper = GRIPPER_OPEN
            yield from self._until_held(chase, "chase", lambda step: self._time_left(env) and not self._at_rest_on_ground_or_deck(env))
            if self._at_rest_on_ground_or_deck(env) and self._time_left(env):
                yield from self._pick_up_from_the_ground(env)
        if self.gripper != GRIPPER_CLOSED:
            raise PlanningFailed("the debris got away from the chasing hand")

    @staticmethod
    def _at_rest_on_ground_or_deck(env) -> bool:
        """Whether the debris has come to rest on the ground or on the mount (the station's deck, the rover): slower
        than ``RESTING_SPEED``, touching it."""
        surfaces = [surface for surface in (getattr(env, "ground", None), env.mount_actor) if surface is not None]
        touching = any(bool(torch.linalg.norm(env.scene.get_pairwise_contact_forces(env.debris, surface)[0]) > 0) for surface in surfaces)
        return touching and float(torch.linalg.norm(env.debris.linear_velocity[0])) < RESTING_SPEED

    def _pick_up_from_the_ground(self, env) -> Iterator[np.ndarray]:
        """Grasp debris resting on the ground (or the mount's deck) from above (as Sample Collection's oracle takes a
        rock): swing to a pre-grasp pose over it, go down, close the fingers."""
        grasp = top_down_grasp_pose(env, env.debris)
        pre_grasp = raised(grasp, PRE_GRASP_HEIGHT)
        start = self.arm_qpos()
        goal = self.free_joint_goal(start, pre_grasp, floor=min(self._tcp_position()[2], pre_grasp.p[2]))
        if goal is None:  # every way there dips below the hand's height: one that keeps the arm off the debris will do
            with self._debris_as_obstacle(env):
                goal = self.free_joint_goal(start, pre_grasp)
        if goal is None:
            raise PlanningFailed("the debris came to rest on the ground where the hand cannot reach over it")
        yield from self.joint_move(goal, "over the debris on the ground")
        yield from self.screw_to(grasp, "down to the debris on the ground", settle_steps=3)
        yield from self.set_gripper(GRIPPER_CLOSED)

    @contextmanager
    def _debris_as_obstacle(self, env) -> Iterator[None]:
        """The debris' oriented bounding box, where it lies now, among the planner's obstacles for the duration."""
        from mani_skill.examples.motionplanning.base_motionplanner.utils import get_actor_obb

        box = get_actor_obb(env.debris).primitive
        obstacle = fcl.CollisionObject(fcl.Box(np.asarray(box.extents, dtype=np.float64)))
        transform = np.array(box.transform, dtype=np.float64)
        if np.linalg.det(transform[:3, :3]) < 0:  # a mirrored frame bounds the same box: make it a rotation
            transform[:3, 2] *= -1.0
        pose = sapien.Pose(transform)
        obstacle.set_transformation(np.concatenate([pose.p, pose.q]))
        world = self.solver.planner.planning_world
        world.set_normal_object(DEBRIS_AT_REST, obstacle)
        try:
            yield
        finally:
            world.remove_normal_object(DEBRIS_AT_REST)

    @staticmethod
    def _time_left(env) -> bool:
        """Whether more than ``RESERVED_STEPS`` of the episode are left."""
        return int(env.steps_remaining()[0]) > RESERVED_STEPS

    def _holding(self, env) -> bool:
        """Whether the fingers are closed and the debris is grasped."""
        return self.gripper == GRIPPER_CLOSED and bool(env.is_grasping(env.debris)[0])

    def _until_held(self, target: Callable[[int], sapien.Pose], what: str, going: Callable[[int], bool]) -> Iterator[np.ndarray]:
        """Servo to ``target`` while ``going(step)`` holds, until the fingers have been closed ``CLOSED_FOLLOW_STEPS``.
        A chase whose servo has found no solution near the joints for ``STUCK_CHASE_STEPS`` in a row steps toward the
        nearest other one (``Oracle.servo``'s ``far_solutions_after``)."""
        closed_steps, step = 0, 0
        while going(step):
            if self.gripper == GRIPPER_CLOSED:
                closed_steps += 1
                if closed_steps > CLOSED_FOLLOW_STEPS:
                    return
            yield from self.servo(target, 1, what, far_solutions_after=STUCK_CHASE_STEPS if what == "chase" else None)
            step += 1

    def _on_debris(self, env, meeting: sapien.Pose, lead: Optional[float] = None, catch_speed: float = CATCH_SPEED) -> sapien.Pose:
        """The hand's next position: moving with the debris, letting it come closer at most ``catch_speed`` (the
        follow's ``CATCH_SPEED``, so that it glides between the fingers instead of being hit); the fingers close once
        its centre is between them. The target is ``lead`` seconds of the debris' motion ahead of the hand (one
        control step unless given), and one step of the closing in."""
        position, velocity = self._debris_state(env)
        hand = self._tcp_position()
        gap = position - hand
        distance = float(np.linalg.norm(gap))
        if distance < CLOSE_RADIUS or (self._touching(env) and self._between_pads(env) >= CLOSE_PAD_OVERLAP):
            self.gripper = GRIPPER_CLOSED
        if self.gripper != GRIPPER_CLOSED and self._tilt == 0.0:  # until they close, keep the fingers across it
            self._grip_orientation = self._across(meeting, self._long_axis(env, 0.0))
        catch_up = min(distance / CATCH_TIME, catch_speed) * gap / max(distance, 1e-9)
        lead = env.control_timestep if lead is None else lead
        return sapien.Pose(hand + velocity * lead + catch_up * env.control_timestep, self._grip_orientation)

    def _between_pads(self, env) -> float:
        """How much of the finger pads the debris would meet if they closed now (its parts' overlaps, at most 1)."""
        if not hasattr(self, "_finger_pad"):
            self._finger_pad = finger_pad_rectangle(env)
        hand = self.tcp_pose()
        return min(1.0, sum(pad_overlap(hand, part, self._finger_pad, OPEN_FINGER_GAP) for part in collision_part_vertices(env.debris)))

    def _across(self, meeting: sapien.Pose, long_axis: np.ndarray) -> np.ndarray:
        """The meeting orientation turned about its approach axis so the fingers close across ``long_axis``,
        whichever of the two such closing directions is nearer the hand's present one."""
        frame = meeting.to_transformation_matrix()
        return self.closings_nearest_first(_facing(frame[:3, 3], -frame[:3, 2], long_axis))[0].q

    def _brake(self, env) -> Iterator[np.ndarray]:
        """Keep the hand moving with the held debris, slowing linearly to a stop."""
        _, velocity = self._debris_state(env)
        position = self._tcp_position()
        dt = env.control_timestep
        for step in range(BRAKE_STEPS):
            position = position + velocity * dt * (1 - (step + 1) / BRAKE_STEPS)
            yield from self.servo(lambda _: sapien.Pose(position, self._grip_orientation), 1, "brake")

    def _tcp_position(self) -> np.ndarray:
        return self.env.agent.tcp.pose.p[0].cpu().numpy().astype(np.float64)

    def _meeting_point(self, env) -> tuple[sapien.Pose, np.ndarray]:
        """The first point of the predicted path the hand can reach before the debris does, and the arm pose. The
        swing there (``swing_acceleration``) is the usual one, else, where no point can be reached in time at it,
        ``FAST_SWING`` times as brisk (so that where the usual swing does, nothing changes)."""
        for acceleration in (1.0, FAST_SWING):
            with self._speed(1.0, acceleration):
                found = self._first_meeting(env)
            if found is not None:
                self.swing_acceleration = acceleration
                return found
        raise PlanningFailed("the debris never passes where the hand can meet it in time")

    def _first_meeting(self, env) -> Optional[tuple[sapien.Pose, np.ndarray]]:
        """``_meeting_point`` at the planner's present speed limits, or None."""
        position, velocity = self._debris_state(env)
        gravity = np.asarray(env.sim_config.scene_config.gravity, dtype=np.float64)
        shoulder = self.solver.base_pose.p + np.array([0.0, 0.0, SHOULDER_HEIGHT])
        start = self.arm_qpos()
        times = np.arange(EARLIEST_MEETING, LATEST_MEETING, TIME_STEP)
        rotations = self._rotations(env, times)
        long_axes = rotations @ self._body_axis(env, longest=True)
        elongated = self._elongated(env)
        spin = float(np.linalg.norm(env.debris.angular_velocity[0].cpu().numpy()))
        thin_axes = rotations @ self._body_axis(env, longest=False) if not elongated and spin <= THIN_SIDE_MOST_SPIN else None
        # a long body is met first where it will lie across its path (so that it comes in between the open fingers
        # rather than end first into the palm), with the hand turned so that it will lie along the pads; failing
        # those, as a compact one; and first of all where, as it will be turned then, it fits the open hand
        passes = ((True, True), (False, True), (False, False)) if elongated else ((False, False),)
        for fitting in (True, False):
            for broadside_only, along_the_fingers in passes:
                found = self._search_meeting(
                    env, start, shoulder, position, velocity, gravity, times, long_axes, broadside_only, along_the_fingers, rotations if fitting else None, thin_axes
                )
                if found is not None:
                    return found
        return None

    def _search_meeting(
        self,
        env,
        start,
        shoulder,
        position,
        velocity,
        gravity,
        times,
        long_axes,
        broadside_only: bool,
        along_the_fingers: bool,
        rotations: Optional[np.ndarray] = None,
        thin_axes: Optional[np.ndarray] = None,
    ):
        """The first meeting (grasp pose, arm joints) on the predicted path, or None: where ``broadside_only``, only
        where the long axis lies across the path; where ``along_the_fingers``, only hands that the body will lie
        along (``_lies_along_the_fingers``), the first of them turned for it (``_along_the_fingers``); given the
        body's ``rotations`` at ``times``, only hands it will fit as it turns on its way in (``_fits_the_open_hand`` at
        each of the rotations ``FIT_WINDOW`` steps either side of its time there), and then also, given its thinnest
        axis at those times (``thin_axes``), a hand closing across it, where the body will lie between its open fingers
        (``ACROSS_THE_THIN_SIDE``; it may reach the palm)."""
        tilts = (ALONG_THE_FINGERS, *TILTS) if along_the_fingers else TILTS
        if rotations is not None and thin_axes is not None:
            tilts = (*tilts, ACROSS_THE_THIN_SIDE)
        for i, (t, long_axis) in enumerate(zip(times, long_axes)):
            point = position + velocity * t + 0.5 * gravity * t * t
            if point[2] < LOWEST_MEETING_HEIGHT or not REACH[0] <= np.linalg.norm(point - shoulder) <= REACH[1]:
                continue
            heading = velocity + gravity * t
            if broadside_only and abs(long_axis @ heading) > BROADSIDE_COSINE * np.linalg.norm(heading):
                continue
            for tilt in tilts:
                if tilt == ALONG_THE_FINGERS:
                    facing = _along_the_fingers(point, heading, long_axis)
                elif tilt == ACROSS_THE_THIN_SIDE:
                    facing = _across_the_thin_side(point, heading, thin_axes[i])
                else:
                    facing = _facing(point, heading, long_axis, tilt)
                if along_the_fingers and not _lies_along_the_fingers(facing, long_axis):
                    continue
                window = rotations[max(i - FIT_WINDOW, 0) : i + FIT_WINDOW + 1] if rotations is not None else ()
                if not all(self._fits_the_open_hand(env, facing, rotation, clear_of_the_palm=tilt != ACROSS_THE_THIN_SIDE) for rotation in window):
                    continue
                for pose in self.closings_nearest_first(facing):
                    for arm in self.ik_solutions(pose):
                        # neither the time-optimal parameterisation nor pacing makes a move shorter than its
                        # fastest joint can make it: too slow at that, it needs neither to be ruled out
                        if self.straight_move_duration(start, arm) + ARRIVAL_MARGIN > t:
                            continue
                        path = self._timed_path(start, arm)
                        if not self._arrives_in_time(path, t):
                            continue
                        path = self.paced(path)
                        if not self._arrives_in_time(path, t) or not self.path_is_free(start, arm):
                            continue
                        if self._clear_of_debris(env, path, point, t):
                            self._tilt = tilt
                            return pose, arm
        return None

    def _arrives_in_time(self, path: np.ndarray, meeting_time: float) -> bool:
        """Whether the hand, moving along ``path`` (one target per control step), is in place ``ARRIVAL_MARGIN``
        before ``meeting_time``. (Pacing a path never shortens it: a path too slow unpaced needs no pacing to be
        ruled out, and pacing, forward kinematics at every step, is the costly part of the search.)"""
        return len(path) * self.env.control_timestep + ARRIVAL_MARGIN <= meeting_time

    def _clear_of_debris(self, env, path: np.ndarray, meeting: np.ndarray, meeting_time: float) -> bool:
        """Whether the arm, moving along ``path`` and then waiting at its end, stays out of the ball the debris
        sweeps (tumbling, it may point any way) until it comes within reach of the fingers at ``meeting``, once
        the hand is there (a slow debris may be near the meeting point long before it arrives: the arm must not swing
        through it on its way)."""
        position, velocity = self._debris_state(env)
        gravity = np.asarray(env.sim_config.scene_config.gravity, dtype=np.float64)
        radius = self._debris_radius(env)
        planner = self.solver.planner
        arrival = len(path) * env.control_timestep
        world = planner.planning_world
        ball = fcl.CollisionObject(fcl.Sphere(radius))
        try:
            # latest first: the arm is likeliest to meet the debris near where they are to meet, and a blocked
            # candidate is ruled out sooner
            for t in np.arange(0.0, meeting_time, SWEEP_TIME_STEP)[::-1]:
                centre = position + velocity * t + 0.5 * gravity * t * t
                if t >= arrival and np.linalg.norm(centre - meeting) < radius + HAND_LENGTH:
                    continue  # the hand is there, waiting for it
                qpos = path[min(int(t / env.control_timestep), len(path) - 1)]
                ball.set_transformation(np.concatenate([centre, [1.0, 0.0, 0.0, 0.0]]))
                world.set_normal_object(DEBRIS_BALL, ball)
                if planner.check_for_env_collision(planner.robot, planner.pad_qpos(qpos), with_point_cloud=False):
                    return False
            return True
        finally:  # the debris' ball is only for this check (the mount and ground are checked by path_is_free)
            if DEBRIS_BALL in world.get_normal_object_names():
                world.remove_normal_object(DEBRIS_BALL)

    def _debris_radius(self, env) -> float:
        """Half the diagonal of the debris' bounding box (it is the same all episode)."""
        if getattr(self, "_radius_of", None) is not env.debris:
            from mani_skill.examples.motionplanning.base_motionplanner.utils import get_actor_obb

            self._radius_of, self._radius = env.debris, float(np.linalg.norm(get_actor_obb(env.debris).primitive.extents)) / 2
        return self._radius

    def _wait_for_debris(self, env, meeting: sapien.Pose) -> Generator[np.ndarray, None, bool]:
        """Hold the open hand still at the meeting pose until the debris is close: True once it has arrived (its
        centre near the grasp point, ``FOLLOW_DISTANCE`` or, for a larger body, ``FOLLOW_REACH_MARGIN`` beyond its
        radius, or touching the hand), False once it moves away from the hand within reach of it
        without having arrived (it struck the arm, or passed beside the hand). On a free-flying servicer the swing
        there has moved and turned the bus (a few centimetres and degrees, enough to put the hand beside the debris'
        path), so the hand is servoed back onto the meeting pose, planned from where the bus is now."""
        self.phase = "waiting for the debris"
        free_flyer = getattr(env, "free_flyer", False)
        within_reach = self._debris_radius(env) + HAND_LENGTH
        follow_distance = max(FOLLOW_DISTANCE, self._debris_radius(env) + FOLLOW_REACH_MARGIN)
        for _ in range(int(LATEST_MEETING / env.control_timestep)):
            position, velocity = self._debris_state(env)
            gap = position - self._tcp_position()
            distance = float(np.linalg.norm(gap))
            if distance < follow_distance or self._touching(env):
                return True
            if distance < within_reach and gap @ velocity > 0:
                return False
            if free_flyer:
                yield from self.servo(lambda _: meeting, 1, "meeting")
            else:
                yield self.hold_action()
        raise PlanningFailed("the debris did not arrive")

    @staticmethod
    def _touching(env) -> bool:
        """Whether the debris touches the hand or a finger."""
        agent = env.agent
        links = (agent.finger1_link, agent.finger2_link, agent.robot.links_map["panda_hand"])
        return any(float(torch.linalg.norm(env.scene.get_pairwise_contact_forces(link, env.debris)[0])) > 0 for link in links)

    def _fits_the_open_hand(self, env, hand: sapien.Pose, rotation: np.ndarray, clear_of_the_palm: bool = True) -> bool:
        """Whether the debris, turned by ``rotation`` with its centre at the grasp point of ``hand``, lies clear of the
        open fingers and (unless not ``clear_of_the_palm``) of the palm (deeper than the fingers' roots), so that it
        can come in between the pads rather than onto a fingertip, or end first into the palm, as the fingers close
        on it."""
        if getattr(self, "_hand_boxes_of", None) is not env.debris:
            corners = finger_box_corners(env)
            rotation_now = env.debris.pose.sp.to_transformation_matrix()[:3, :3]
            centre = self._debris_state(env)[0]
            self._hand_boxes_of = env.debris
            self._fingers = [(box.min(axis=0), box.max(axis=0)) for box in corners]
            self._palm_depth = float(min(box[:, 2].min() for box in corners))
            self._body_parts = [(part - centre) @ rotation_now for part in collision_part_vertices(env.debris)]
        to_hand = rotation.T @ hand.to_transformation_matrix()[:3, :3]
        for part in self._body_parts:
            local = part @ to_hand
            if (clear_of_the_palm and float(local[:, 2].min()) < self._palm_depth) or any(_meets_box(local, *finger) for finger in self._fingers):
                return False
        return True

    @staticmethod
    def _long_axis(env, time: float = 0.0) -> np.ndarray:
        """The debris' longest axis (its bounding box's) as it will point at ``time``, tumbling freely."""
        return DebrisCaptureOracle._rotations(env, np.array([time]))[0] @ DebrisCaptureOracle._body_axis(env, longest=True)

    @staticmethod
    def _body_axis(env, longest: bool) -> np.ndarray:
        """The debris' longest (else shortest) axis (its bounding box's) in its own frame."""
        from mani_skill.examples.motionplanning.base_motionplanner.utils import get_actor_obb

        box = get_actor_obb(env.debris)
        pick = np.argmax if longest else np.argmin
        axis = np.asarray(box.primitive.transform)[:3, int(pick(box.primitive.extents))]
        return env.debris.pose.sp.to_transformation_matrix()[:3, :3].T @ axis

    @staticmethod
    def _rotations(env, times: np.ndarray) -> np.ndarray:
        """(T, 3, 3) the debris' rotations at each of ``times`` (ascending, seconds from now), tumbling freely from its
        present angular velocity (``debris_paths.tumbling_rotations``: Euler's equations with its own inertia, not a
        constant angular velocity)."""
        rotation = env.debris.pose.sp.to_transformation_matrix()[:3, :3]
        body = env.debris._bodies[0]
        principal_axes = sapien.Pose(q=body.cmass_local_pose.q).to_transformation_matrix()[:3, :3]
        spin = env.debris.angular_velocity[0].cpu().numpy().astype(np.float64)
        return tumbling_rotations(rotation, spin, np.asarray(body.inertia), principal_axes, times)

    @staticmethod
    def _elongated(env) -> bool:
        from mani_skill.examples.motionplanning.base_motionplanner.utils import get_actor_obb

        extents = np.sort(np.asarray(get_actor_obb(env.debris).primitive.extents))
        return bool(extents[2] >= ELONGATED_RATIO * extents[1])

    @staticmethod
    def _debris_state(env) -> tuple[np.ndarray, np.ndarray]:
        return env.debris.pose.p[0].cpu().numpy().astype(np.float64), env.debris.linear_velocity[0].cpu().numpy().astype(np.float64)


def _meets_box(vertices: np.ndarray, low: np.ndarray, high: np.ndarray) -> bool:
    """Whether the convex polytope with ``vertices`` meets the axis-aligned box from ``low`` to ``high``."""
    for axis in range(3):
        vertices = clip(clip(vertices, np.eye(3)[axis], high[axis]), -np.eye(3)[axis], -low[axis])
    return len(vertices) > 0


def _lies_along_the_fingers(hand: sapien.Pose, long_axis: np.ndarray) -> bool:
    """Whether a long body with ``long_axis`` lies more along the pads' width than along the hand's approach (end
    first into the palm) or its closing axis (across the fingers' gap, which it is longer than)."""
    frame = hand.to_transformation_matrix()[:3, :3]
    cosines = np.abs(frame.T @ (long_axis / np.linalg.norm(long_axis)))
    return bool(cosines[0] >= max(cosines[1], cosines[2]))


def _along_the_fingers(point: np.ndarray, velocity: np.ndarray, long_axis: np.ndarray) -> sapien.Pose:
    """A grasp pose at ``point`` for a long body arriving with ``velocity``, its ``long_axis`` along the hand's x
    (the pads' width): the hand faces the body as squarely as it can across that axis, so that a body arriving
    broadside comes straight into the open hand and one arriving end first slides along the channel between the
    pads; seen from above where it arrives end first along a level path."""
    axis = long_axis / np.linalg.norm(long_axis)
    approach = _approach_across(axis, velocity)
    return tcp_pose_with_axes(point, approach, np.cross(approach, axis))


def _across_the_thin_side(point: np.ndarray, velocity: np.ndarray, thin_axis: np.ndarray) -> sapien.Pose:
    """A grasp pose at ``point`` closing along a body's ``thin_axis``, facing it as squarely as it can across that axis
    (as ``_along_the_fingers``): a flat body arriving edge first comes straight in between the pads."""
    axis = thin_axis / np.linalg.norm(thin_axis)
    return tcp_pose_with_axes(point, _approach_across(axis, velocity), axis)


def _approach_across(axis: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """The unit approach across the unit ``axis`` nearest against ``velocity``; where that lies almost along the axis,
    nearest pointing down, else sideways."""
    for wanted in (-velocity / np.linalg.norm(velocity), np.array([0.0, 0.0, -1.0])):
        across = wanted - (wanted @ axis) * axis
        if np.linalg.norm(across) >= 0.3:
            return across / np.linalg.norm(across)
    sideways = np.array([0.0, 1.0, 0.0]) - axis[1] * axis  # the axis is near vertical here, so this is long
    return sideways / np.linalg.norm(sideways)


def _facing(point: np.ndarray, velocity: np.ndarray, long_axis: np.ndarray, tilt: float = 0.0) -> sapien.Pose:
    """A grasp pose at ``point`` whose open fingers take the incoming debris between them: pointing against its
    velocity (``tilt`` 0; closing across the debris' long axis, so a long body lies along the fingers), or
    tilted by ``tilt`` radians toward pointing down, closing across the path, so that the debris glides in
    along the channel the two finger pads leave open (the Panda reaches some of these poses much sooner)."""
    along = velocity / np.linalg.norm(velocity)
    if tilt == 0.0:
        approach = -along
        closing = np.cross(approach, long_axis)
        if np.linalg.norm(closing) < 0.2:  # the long axis points at the hand: any closing direction will do
            closing = np.cross(approach, [0.0, 0.0, 1.0])
    else:
        down = np.array([0.0, 0.0, -1.0]) + along[2] * along  # straight down, less its part along the path
        if np.linalg.norm(down) < 0.3:  # falling almost straight down: tilt sideways instead
            down = np.array([0.0, 1.0, 0.0]) - along[1] * along
        down /= np.linalg.norm(down)
        approach = np.cos(tilt) * -along + np.sin(tilt) * down
        closing = np.cross(approach, along)
    return tcp_pose_with_axes(point, approach, closing)
