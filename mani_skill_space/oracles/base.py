"""Motion-planning oracles as step-by-step policies, on ManiSkill's mplib-based Panda planner.

An oracle's ``plan(env)`` is a generator: it plans one segment at a time with
``PandaArmMotionPlanningSolver`` (in dry-run mode, so the planner never steps the env itself), yields the
segment's ``pd_joint_pos`` actions one by one, and plans the next segment from the state the env actually
reached. The caller owns the loop, so the same oracle serves the evaluation CLI (any number of steps, any
wrappers) and the demo generator (``RecordEpisode``). Every planner call used here is deterministic (screw
motions, single-start IK, time-optimal parameterisation of straight joint-space paths; no RRT), so the same
seed gives the same demonstration.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
from contextlib import contextmanager
from typing import Callable, Generator, Iterator, Optional

import numpy as np
import sapien
from mani_skill.examples.motionplanning.panda.motionplanner import PandaArmMotionPlanningSolver
from scipy.spatial.transform import Rotation

from mani_skill_space.policy import Policy

GRIPPER_OPEN = 1.0
GRIPPER_CLOSED = -1.0
HALF_TURN_ABOUT_APPROACH = np.array([0.0, 0.0, 0.0, 1.0])
"""wxyz: half a turn about the TCP's z (approach) axis."""
TCP_RAMP_STEPS = 5
"""Steps over which an oracle with a ``tcp_pace`` speeds up to it (and slows down from it)."""
SURFACE_POINTS_PER_PART = 256
FREE_FLYER_CORRECTIONS = 3
FREE_FLYER_TOLERANCE = 0.003
"""m: on a free-flying servicer a screw motion is followed by up to this many corrections, planned from where the bus
has drifted, until the TCP is this close to its goal."""
POINT_SPACING = 0.02
"""About one obstacle point per 2 x 2 cm of surface: no arm link fits between them."""
GROUND_REACH = 1.0
GROUND_MARGIN = 0.02
FINE_SCREW_STEP = 0.02
"""rad: a finer joint step for mplib's screw motions (``Oracle.screw_step``). mplib follows the screw with first-order
(Jacobian) steps of that size and never corrects their drift: at its default, 0.1, 39 of the 98 screw motions of the
traced Peg-in-Hole episodes ended 5-11 mm from their goal; at 0.02 none did."""
CATCH_UP_STEPS = 6
CATCH_UP_TOLERANCE = (0.01, 0.05)
"""At most this many steps (m, rad: until the hand is this close to its goal) ``Oracle.catch_up`` holds a motion's
last target under a TCP controller."""
SETTLE_MOST_STEPS = 20
SETTLE_TOLERANCE = 0.005
"""At most this many steps (rad: until every arm joint is this close to it) ``Oracle.settle`` holds the last joint
target sent."""
SERVO_JOINT_STEP = 0.3
"""rad: the most a servo step moves any joint's target (6 rad/s at 20 Hz, over twice the Panda's joint speed limits).
Near a joint limit, IK from the present joints can return a solution on another branch (seed 64005 of Solar Panel
Assembly, orbit: joint 3 from -2.8 to +2.8 rad in one step of the panel's lift), and the arm whipped round to it and
flung the panel away."""
FAR_STEP_PACE = (0.02, 0.15)
"""(metres, radians): the most the hand moves or turns in a servo step toward another IK solution
(``Oracle._step_to_far_solution``). Every joint at ``SERVO_JOINT_STEP`` swept the hand 95 mm in one step into a 200 mm
peg 2 cm from it (Debris Capture, asteroid, tuning seed 63029), which flew off at 1.9 m/s."""
FINGERS_STILL = 1e-4
"""m: a finger that moves less than this in a control step has stopped closing (``wait_for_grasp``)."""
FINGERS_SHUT = 5e-4
"""m: fingers closed this far (each) hold nothing between them: the grasp has missed, whatever the wait."""
JOINT_VELOCITY_LIMIT = 2.0
JOINT_ACCELERATION_LIMIT = 4.0
"""rad/s and rad/s^2 for every arm joint: about 0.9x the Panda's velocity limits (ManiSkill's solutions use 0.9
rad/s, too slow for a 7.5 s episode that swings the arm to a bin behind it) with gentle accelerations, which
the joint PD controller tracks closely."""


class PlanningFailed(RuntimeError):
    pass


class GraspMissed(PlanningFailed):
    """The closed fingers hold nothing (``Oracle.wait_for_grasp``): the hand may let go and try another grasp."""


class Oracle(Policy):
    control_mode = "pd_joint_pos"
    tcp_pace: Optional[tuple[float, float]] = None
    """(metres, radians): where set, every motion is retimed to move the TCP target this far per control step (or
    turn it this far, whichever comes first), a pace ``pd_ee_delta_pose`` (0.1 m / 0.1 rad per step, less its PD
    lag) follows step for step: the demonstrations then convert to it without stretching."""
    tcp_speed_limit: Optional[tuple[float, float]] = None
    """(metres, radians): where set (and no ``tcp_pace``), a motion whose TCP would move or turn farther than this in
    a control step is slowed there to this (and nowhere else): the end-effector controller clips each step's delta
    to its own limits, so an oracle acting through it plans within them (``oracles.end_effector`` sets it)."""
    arm_follower: Optional[Callable[[np.ndarray, np.ndarray], Optional[np.ndarray]]] = None
    """Where set (``oracles.end_effector`` sets it), the arm joints in which the controller leaves the arm when it is sent a
    joint path (arm joints at each step) from a start (``(start, path)``; None where it stalls): a TCP controller follows
    the hand's pose, not the joints, and its IK, re-solved from the joints as they are, settles the arm's redundancy
    its own way (``joint_move_end``)."""
    line_follower: Optional[Callable[[np.ndarray, sapien.Pose, tuple[float, float]], Optional[np.ndarray]]] = None
    """Where set (``oracles.end_effector`` sets it), the arm joint targets, one per control step within a speed limit,
    along which a TCP controller takes the hand in a straight line (moving evenly, turning evenly about one axis) from
    where arm joints ``start`` put it to a pose (world frame), given ``(start, pose, limit)`` (``limit``: metres,
    radians per step); None where it stalls short of the pose (``straight_line_path``)."""
    arc_follower: Optional[Callable[[np.ndarray, sapien.Pose, tuple[float, float], int, bool], Optional[np.ndarray]]] = None
    """Where set (``oracles.end_effector`` sets it), the arm joint targets, one per control step within a speed limit,
    along which a TCP controller takes the hand round the arm's base (its first joint's axis), given ``(start, pose,
    limit, way, carried)`` (``way``: +1 anticlockwise seen from above, -1 clockwise; ``carried``: the hand turned
    round with the sweep, as the first joint carries it, as well as evenly to its goal orientation); None where it
    stalls short of the pose (``arcs_round_base``)."""
    straight_lines_under_tcp_control: bool = False
    """Whether, acting through a TCP controller (``line_follower`` set), the oracle moves the hand in straight lines
    (``straight_line_path``) where mplib's screw motion has no path (where there is no line either, round the arm's
    base, ``arcs_round_base``, if that is quicker than a joint-space move) and, in the motions that ask for one,
    instead of a joint-space swing. That controller follows the hand's poses, so a joint-space move to another IK
    solution makes it take the hand along the whole whirl of the joints (procedural peg, Moon, seed 6045: 5.9 rad of
    turning and 0.86 m of travel for a net 1.5 rad and 0.2 m, 122 of the episode's 200 steps); mplib's screw motion
    stops at the first joint limit its Jacobian steps run into, where the controller's IK, stepped along the line,
    gets round it. Solar Panel Assembly's oracle does (its four pegs and panel now fit the 1000 steps); the single
    peg's did not gain (see the README's *Straight lines of the hand*): it takes the hand's line only where that is
    quicker (``quicker_lines_under_tcp_control``; its swing over the hole, ``PegInserter._swing_over``)."""
    quicker_lines_under_tcp_control: bool = False
    """Whether, acting through a TCP controller (``line_follower`` set), the oracle takes the hand's straight line
    (``hand_line``) instead of mplib's screw motion or a joint-space move wherever the line takes fewer control steps
    (``_motion_path``). A screw motion turns the hand about a screw axis, and a long turn swings it round a wide helix
    (procedural peg, Moon, seed 6037: the lift took 19 steps as a screw motion and 9 as the line, and the peg, which
    had run out of time in the push, was in at step 195). The single peg's oracle and Solar Panel Assembly's do."""
    free_space_translation_scale: float = 1.0
    """Under a TCP controller (``tcp_speed_limit`` set), how many times farther than ``tcp_speed_limit`` allows the TCP
    may move in a step in the motions planned at more than the usual joint accelerations (an oracle's brisk free-space
    motions, e.g. an empty hand's to its next grasp)."""
    via_height: Optional[float] = None
    """Where set (m, world z), an oracle moving in straight lines (``moves_in_straight_lines``) may also take the hand
    up to this height, across and down (``over_the_top_path``) where mplib's screw motion and the straight line have no
    path, if that is quicker than the joint-space move or the arc round the base."""
    path_check_step: Optional[float] = None
    """Where set (radians), ``path_is_free`` checks a joint-space move at least this often along it, not only at
    its 20 samples: thin obstacles that stand up high (e.g. inserted pegs) can fall between the samples of a long
    swing."""

    screw_step: float = 0.1
    """rad: the joint step of the screw motions (mplib's default; the insertion oracles, whose pegs go into holes 1 mm wider
    than them, use ``FINE_SCREW_STEP``)."""

    plans_with_the_fingers_as_they_are: bool = False
    """Where set, the planner's Panda has its fingers where the simulated ones are (open, or closed on what the hand
    holds) when it checks a motion for collisions. mplib's model otherwise keeps them closed, i.e. an open finger's
    outer side 4 cm farther out than planned: room enough to sweep through a thin peg standing beside the path."""

    retreats_straight_up: bool = False
    """Where set, ``retreat_up`` goes straight up as far as the hand can before it takes any other motion. The open
    fingers still straddle the part just let go, which the planner does not see: traced on Multi-Peg, orbit, seed
    62019, the hand had no straight motion 0.2 m up (a joint limit), and the joint-space move there swung it 5 cm
    sideways, and the fingers dragged the peg out of its hole, where 0.12 m straight up was free. Solar Panel
    Assembly's oracle does not: with it, the motions after its retreats found no plan more often (the panel's
    pre-grasp, the next peg's grasp; its suite's seeds 4100-4119, every configuration: 144 -> 132 of 160, none gained;
    not traced)."""

    _planned_fingers: Optional[np.ndarray] = None
    """The finger joints of ``fingers_planned_at``'s block, inside one."""

    def reset(self, env, seed: int) -> None:
        self.env = env.unwrapped
        self.gripper = GRIPPER_OPEN
        self.last_action: Optional[np.ndarray] = None
        self.done = False
        self.failure: Optional[str] = None
        self.start_qpos = self.arm_qpos().copy()
        """The arm's joints when the episode started."""
        self.servo_held_steps = 0
        """Steps in a row that ``servo`` has held its previous target for want of a solution near the joints."""
        self.phase = "start"
        """What the plan is doing now (the motion under way, e.g. ``"pre-grasp"``, ``"insert"``): the runners report it
        for an episode that ends before the plan does."""
        self._actions = self.plan(self.env)

    def act(self, obs) -> np.ndarray:
        """The plan's next action; once the plan has ended, its last target is held (not the joints' current
        positions, which would let go of whatever the arm is pressing on)."""
        if not self.done:
            try:
                self.last_action = next(self._actions)
                return self.last_action
            except StopIteration:
                self.done = True
            except PlanningFailed as error:
                self.done, self.failure = True, str(error)
        return self.last_action if self.last_action is not None else self.hold_action()

    def plan(self, env) -> Iterator[np.ndarray]:
        raise NotImplementedError

    # ------------------------------------------------------------------ building blocks
    def make_solver(self, env, obstacles: Optional[np.ndarray] = None) -> PandaArmMotionPlanningSolver:
        """ManiSkill's Panda planner at the arm's mount, aware of the static mount (rover, bin, ...), the ground
        and any ``obstacles`` points (world frame)."""
        solver_class = _ServicerArmSolver if getattr(env, "free_flyer", False) else PandaArmMotionPlanningSolver
        solver = solver_class(
            env,
            debug=False,
            vis=False,
            base_pose=env.agent.robot.pose,
            visualize_target_grasp_pose=False,
            print_env_info=False,
            joint_vel_limits=JOINT_VELOCITY_LIMIT,
            joint_acc_limits=JOINT_ACCELERATION_LIMIT,
        )
        # a free-flying servicer's bus moves with the arm, so points fixed where it was would soon stand inside it
        # (the arm never reaches back under its own base)
        points = standing_obstacle_points(None if getattr(env, "free_flyer", False) else env.mount)
        if obstacles is not None:
            points = np.concatenate([points, obstacles])
        solver.add_collision_pts(points)
        solver.use_point_cloud = True
        self.solver = solver
        self._obstacles_in_use = solver.all_collision_pts
        return solver

    def tcp_pose(self) -> sapien.Pose:
        """The TCP's world pose now."""
        return self.env.agent.tcp.pose.sp

    def closings_nearest_first(self, pose: sapien.Pose) -> tuple[sapien.Pose, sapien.Pose]:
        """``pose`` and the same grasp half a turn about its approach axis (the fingers are alike), the one whose
        fingers close nearer the way the hand's close now first: the hand turns less to get there (in
        ``pd_ee_delta_pose``, which turns the hand at most 0.1 rad a step, up to seconds less)."""
        turned = wrist_turned(pose)
        closing_now = self.tcp_pose().to_transformation_matrix()[:3, 1]
        return (pose, turned) if pose.to_transformation_matrix()[:3, 1] @ closing_now >= 0 else (turned, pose)

    def arm_qpos(self) -> np.ndarray:
        return self.env.agent.controller.controllers["arm"].qpos[0].cpu().numpy()

    def hold_action(self) -> np.ndarray:
        return np.hstack([self.arm_qpos(), self.gripper]).astype(np.float32)

    def screw_to(self, pose: sapien.Pose, what: str, settle_steps: int = 0, speed: float = 1.0, acceleration: float = 1.0) -> Iterator[np.ndarray]:
        """Motion of the TCP to ``pose`` (``_motion_path``: a screw motion, as a rule) at ``speed``
        times the usual joint limits (and ``acceleration`` times the usual accelerations, on top); ``settle_steps`` more
        steps hold the goal so the arm catches up."""
        self.phase = what
        # on a free-flying servicer the motion moves the bus, so the hand ends off the goal by the bus's drift:
        # a few shorter motions planned from where the bus is then close in on it
        corrections = FREE_FLYER_CORRECTIONS if getattr(self.env, "free_flyer", False) else 0
        for correction in range(1 + corrections):
            if correction and np.linalg.norm(self.tcp_pose().p - pose.p) < FREE_FLYER_TOLERANCE:
                break
            positions = self._planned_motion(self.arm_qpos(), pose, acceleration, speed)
            if positions is None and (yield from self.settle()):
                positions = self._planned_motion(self.arm_qpos(), pose, acceleration, speed)
            if positions is None:
                raise PlanningFailed(f"no motion to the {what} pose")
            yield from self._follow(self.paced(positions, acceleration=acceleration), retime=False)
        yield from self._follow(np.repeat(positions[-1:], settle_steps, axis=0), retime=False)

    def settle(self, most_steps: int = SETTLE_MOST_STEPS) -> Generator[np.ndarray, None, bool]:
        """Hold the last joint target sent until every arm joint is within ``SETTLE_TOLERANCE`` of it, at most
        ``most_steps`` steps; returns whether it held any. ``screw_to`` plans again from there where it finds no motion
        from where the arm is: the plan was checked from where the motion before ends, and the arm trails its targets
        (traced on Solar Panel Assembly, procedural, Earth, seed 64021: 0.04 rad behind at the end of the brisk move to
        the third peg's pre-grasp pose, from where the straight way in to the grasp ran into an obstacle; from the
        target itself it did not). The insertions' line-up over the hole does the same (``PegInserter._push_in``)."""
        if self.last_action is None:
            return False
        target = self.last_action[: len(self.arm_qpos())]
        return (yield from self._hold_last_action(lambda: np.abs(self.arm_qpos() - target).max() <= SETTLE_TOLERANCE, most_steps))

    def _hold_last_action(self, arrived: Callable[[], bool], most_steps: int) -> Generator[np.ndarray, None, bool]:
        """Send the last action again until ``arrived()`` (checked before each step), at most ``most_steps`` steps;
        returns whether it sent any."""
        for step in range(most_steps):
            if arrived():
                return step > 0
            yield self.last_action
        return most_steps > 0

    def catch_up(self, pose: sapien.Pose, most_steps: int = CATCH_UP_STEPS) -> Iterator[np.ndarray]:
        """Acting through a TCP controller (``tcp_speed_limit`` set), hold the last target sent until the hand is within
        ``CATCH_UP_TOLERANCE`` of ``pose``, at most ``most_steps`` steps; in joint control, nothing. The hand lags its
        targets by about two control steps, 0.1 m at the end of a brisk motion, and the motion after it starts from
        where the arm is: traced on Solar Panel Assembly in ``pd_ee_delta_pose`` (procedural, Moon, seed 6021, the
        fourth peg), the straight way in to the grasp, planned from the pre-grasp pose, ran into the peg from 9 cm short
        of it, and the joint-space move taken instead whirled the hand 2.2 m round for 79 steps."""
        if self.tcp_speed_limit is None or self.last_action is None:
            return

        def hand_there() -> bool:
            hand = self.tcp_pose()
            return poses_within((hand.p, hand.q), (pose.p, pose.q), CATCH_UP_TOLERANCE)

        yield from self._hold_last_action(hand_there, most_steps)

    def line_to(self, pose: sapien.Pose, what: str, settle_steps: int = 0) -> Iterator[np.ndarray]:
        """Under a TCP controller (``line_follower`` set), the hand in a straight line to ``pose`` at the oracle's speed
        limit (``tcp_step_limit``; each step's joints the controller's own IK), where the controller follows it with the
        arm clear of collisions; else (in joint control, or with no such line) ``screw_to``. ``settle_steps`` more steps
        hold the goal. For the short moves of a peg over its hole (mplib's screw motion is a straight line of the hand
        too, but timed by the joints' accelerations): traced on a procedural peg (Moon, seed 60041) in
        ``pd_ee_delta_pose``, the tip's 7 cm down to its pre-insert pose, with the lag the swing before had left, took 18
        steps as a screw motion and 12 as the line."""
        if self.line_follower is not None:
            path = self.hand_line(self.arm_qpos(), pose)
            if path is not None:
                self.phase = what
                yield from self._follow(np.concatenate([path, np.repeat(path[-1:], settle_steps, axis=0)]), retime=False)
                return
        yield from self.screw_to(pose, what, settle_steps)

    def _plan_with_the_fingers_now(self) -> None:
        """Where ``plans_with_the_fingers_as_they_are``, the planner's finger joints set to the simulated ones, or to
        those of ``fingers_planned_at`` inside its block (the arm joints of every check come from the caller;
        ``pad_qpos`` fills the rest from the model)."""
        if not self.plans_with_the_fingers_as_they_are:
            return
        model = self.solver.planner.robot
        qpos = model.get_qpos()
        fingers = self.finger_qpos() if self._planned_fingers is None else self._planned_fingers
        qpos[len(qpos) - len(fingers) :] = fingers
        model.set_qpos(qpos, True)

    @contextmanager
    def fingers_planned_at(self, finger_qpos: np.ndarray):
        """Inside the block, an oracle that ``plans_with_the_fingers_as_they_are`` plans with its fingers at
        ``finger_qpos`` instead: for the motions that will carry an object the open hand has not taken yet, the
        fingers as they will be then, closed on it (blocks nest, and each restores the fingers in use before it)."""
        previous = self._planned_fingers
        self._planned_fingers = np.asarray(finger_qpos, dtype=np.float64)
        try:
            yield
        finally:
            self._planned_fingers = previous

    def _plan_from_the_base_now(self) -> None:
        """On a free-flying servicer, plan from the bus's pose now (it moves as the arm does)."""
        if getattr(self.env, "free_flyer", False):
            base = self.env.agent.robot.pose.sp
            self.solver.base_pose = base
            self.solver.planner.set_base_pose(np.hstack([base.p, base.q]))

    @contextmanager
    def obstacles_only(self, choose: Callable[[np.ndarray], np.ndarray]):
        """Plan, inside the block, with the obstacle points that ``choose`` makes of the solver's own (e.g. all but
        a keep-out where the fingers must go, or more around something to keep clear of); blocks nest, and each
        restores the points in use before it."""
        previous = getattr(self, "_obstacles_in_use", self.solver.all_collision_pts)
        chosen = choose(self.solver.all_collision_pts)
        self._plan_with_obstacles(chosen)
        try:
            yield
        finally:
            self._plan_with_obstacles(previous)

    def _plan_with_obstacles(self, points: np.ndarray) -> None:
        """Hand the planner ``points`` as its obstacles, unless they are the ones it has: rebuilding its point cloud
        takes about 30 ms, and a block nested in one with the same points would rebuild it twice for nothing."""
        if not np.array_equal(points, self._obstacles_in_use):
            self.solver.planner.update_point_cloud(points)
        self._obstacles_in_use = points

    @contextmanager
    def _speed(self, scale: float, acceleration_scale: float = 1.0):
        planner = self.solver.planner
        velocity, acceleration = planner.joint_vel_limits, planner.joint_acc_limits
        planner.joint_vel_limits, planner.joint_acc_limits = velocity * scale, acceleration * scale * acceleration_scale
        try:
            yield
        finally:
            planner.joint_vel_limits, planner.joint_acc_limits = velocity, acceleration

    def _motion_path(self, start: np.ndarray, pose: sapien.Pose, acceleration: float = 1.0) -> Optional[np.ndarray]:
        """The joint path of ``screw_to``'s motion from ``start`` to ``pose`` (within ``_speed``): mplib's screw motion,
        else ``_path_without_screw``; for a brisk motion (``acceleration`` above 1) of an oracle moving in straight
        lines, the hand's arc round the arm's base instead where that is quicker than the screw (a screw from one side
        of the base to the other folds the arm over rather than turning it round, and the next long motion from there
        must turn the hand about as far: traced on Solar Panel Assembly, Moon, seed 6018, the panel's pre-grasp and
        swing took 65 and 62 steps); where the oracle takes the quicker lines (``quicker_lines_under_tcp_control``), the
        hand's straight line instead where it takes fewer steps than the screw; None if there is no motion."""
        screw = self._screw_path(start, pose)
        if screw is None:
            return self._path_without_screw(start, pose, acceleration)
        # pacing the screw is costly: only where something is weighed against it, and once
        screw_steps = functools.cache(lambda: len(self.paced(screw, start, acceleration)))
        line = self._quicker_line(start, pose, acceleration)
        if line is not None and len(line) < screw_steps():
            return line
        if acceleration > 1.0:
            arcs = self.arcs_round_base(start, pose, acceleration)
            if arcs and len(arcs[0]) < screw_steps():
                return arcs[0]
        return screw

    def _path_without_screw(self, start: np.ndarray, pose: sapien.Pose, acceleration: float = 1.0) -> Optional[np.ndarray]:
        """Where mplib's screw motion has no path from ``start`` to ``pose``: the hand's straight line there where the
        oracle moves in them (``straight_line_path``); where there is none, the quickest (paced at ``acceleration``) of
        the hand's arc round the arm's base (``arcs_round_base``: from one side of the base to the other, a joint-space
        move may whirl the hand round for 130 steps where the arc takes 40), its path up, across and down
        (``over_the_top_path``), the hand's straight line where the oracle takes the quicker lines
        (``quicker_lines_under_tcp_control``) and the joint-space move to the nearest collision-free IK solution; None
        if there is none."""
        line = self.straight_line_path(start, pose, acceleration)
        if line is not None:
            return line
        goal = self.free_joint_goal(start, pose)
        joint = None if goal is None else self._timed_path(start, goal)  # screw_to paces it
        over_the_top = self.over_the_top_path(start, pose, acceleration)
        hand_paths = self.arcs_round_base(start, pose, acceleration)[:1]
        # an oracle moving in straight lines has just found no hand line: the same line cannot be quicker
        quicker_line = None if self.moves_in_straight_lines else self._quicker_line(start, pose, acceleration)
        hand_paths += [path for path in (over_the_top, quicker_line) if path is not None]
        quickest = min(hand_paths, key=len, default=None)
        if quickest is not None and (joint is None or len(quickest) < len(self.paced(joint, start, acceleration))):
            return quickest
        return joint

    def _quicker_line(self, start: np.ndarray, pose: sapien.Pose, acceleration: float = 1.0) -> Optional[np.ndarray]:
        """Where the oracle takes the quicker lines (``quicker_lines_under_tcp_control``) under a TCP controller, the
        hand's straight line from ``start`` to ``pose`` (``hand_line``), for ``_motion_path`` to weigh; else None."""
        if not self.quicker_lines_under_tcp_control or self.line_follower is None:
            return None
        return self.hand_line(start, pose, acceleration)

    def over_the_top_path(self, start: np.ndarray, pose: sapien.Pose, acceleration: float = 1.0) -> Optional[np.ndarray]:
        """Where the oracle moves in straight lines and has a ``via_height``, the arm joint targets that take the hand
        straight up to that height from where ``start`` puts it, straight across to above ``pose`` (turning to its
        orientation on the way) and straight down to it (each line ``straight_line_path``, chained from where the
        controller leaves the arm), if the controller gets there with the arm clear of collisions; else None."""
        if not self.moves_in_straight_lines or self.via_height is None:
            return None
        positions, rotations = self._tcp_poses([start])
        height = max(self.via_height, float(positions[0][2]), float(pose.p[2]))
        up = sapien.Pose([*positions[0][:2], height], np.roll(rotations[0].as_quat(), 1))
        paths, arm = [], np.asarray(start)
        for waypoint in (up, at_height(pose, height), pose):
            (position,), (rotation,) = self._tcp_poses([arm])
            if poses_within((waypoint.p, waypoint.q), (position, np.roll(rotation.as_quat(), 1)), (1e-3, 1e-3)):
                continue  # already there (a hand at the height goes straight across)
            path = self.straight_line_path(arm, waypoint, acceleration)
            if path is None:
                return None
            paths.append(path)
            arm = path[-1]
        return np.concatenate(paths) if paths else None

    def free_joint_goal(self, start: np.ndarray, pose: sapien.Pose, floor: Optional[float] = None) -> Optional[np.ndarray]:
        """The IK solution for ``pose`` nearest ``start`` that a straight joint move from ``start`` reaches
        without collision (and, given ``floor``, with the TCP never below that height), if any."""
        for goal in self.ik_solutions(pose, near=start):
            if (floor is None or self.tcp_path(start, goal)[0][:, 2].min() >= floor) and self.path_is_free(start, goal):
                return goal
        return None

    def motion_end(self, start: np.ndarray, pose: sapien.Pose, acceleration: float = 1.0) -> Optional[np.ndarray]:
        """Where ``screw_to(pose, acceleration=acceleration)`` from ``start`` would leave the arm (``_motion_path``, as
        ``_followed_end``), or None if it would fail: for checking a whole plan before moving."""
        path = self._planned_motion(start, pose, acceleration)
        return None if path is None else self._followed_end(start, path, acceleration)

    def _followed_end(self, start: np.ndarray, path: np.ndarray, acceleration: float = 1.0) -> Optional[np.ndarray]:
        """Where the arm ends after ``path`` (joints, one row a waypoint, from ``start``): its last joints, or, acting
        through a TCP controller (``arm_follower``), where the controller's IK leaves the arm sent the path as ``paced``
        sends it (None where it stalls short). The hand ends at the path's last pose either way, but the arm may not:
        traced on Solar Panel Assembly in ``pd_ee_delta_pose`` (procedural, Moon, seed 6000, the third peg), a screw
        motion to the pre-grasp pose planned to end with the first joint at -1.91 rad ended at -0.07, the second joint
        at its limit, and the grasp motion planned from the planned end stalled 44 mm short of the peg."""
        arm_path = np.asarray(path)[:, : len(start)]
        if not len(arm_path):  # mplib's screw of (almost) no length
            return np.asarray(start)
        if self.arm_follower is None:
            return arm_path[-1]
        return self.arm_follower(start, self.paced(arm_path, start, acceleration))

    def motion_steps(self, start: np.ndarray, pose: sapien.Pose, acceleration: float = 1.0) -> Optional[int]:
        """How many control steps ``screw_to(pose, acceleration=acceleration)`` from ``start`` would take (as ``paced``
        sends it, without settling), or None if it would fail."""
        path = self._planned_motion(start, pose, acceleration)
        return None if path is None else len(self.paced(path, start, acceleration))

    def _planned_motion(self, start: np.ndarray, pose: sapien.Pose, acceleration: float, speed: float = 1.0) -> Optional[np.ndarray]:
        """``_motion_path`` planned at ``speed`` times the usual joint limits (and ``acceleration`` times the usual
        accelerations, on top)."""
        with self._speed(speed, acceleration):
            return self._motion_path(start, pose, acceleration)

    def screw_end(self, start: np.ndarray, pose: sapien.Pose) -> Optional[np.ndarray]:
        """Arm joints where the screw motion of the TCP from ``start`` to ``pose`` ends (as ``_followed_end``), or None if
        there is none."""
        positions = self._screw_path(start, pose)
        return None if positions is None else self._followed_end(start, positions)

    def straight_line_path(self, start: np.ndarray, pose: sapien.Pose, acceleration: float = 1.0) -> Optional[np.ndarray]:
        """Where the oracle moves in straight lines (``moves_in_straight_lines``), the arm joint targets that take the hand
        in a straight line from where ``start`` puts it to ``pose``, if the controller gets there with the arm clear of
        collisions all the way; else None. The hand goes as fast as ``paced`` lets a motion at ``acceleration``."""
        if not self.moves_in_straight_lines:
            return None
        return self.hand_line(start, pose, acceleration)

    def hand_line(self, start: np.ndarray, pose: sapien.Pose, acceleration: float = 1.0) -> Optional[np.ndarray]:
        """The arm joint targets along which the TCP controller (``line_follower``) takes the hand in a straight line from
        where ``start`` puts it to ``pose``, as fast as ``paced`` lets a motion at ``acceleration``, if it gets there with
        the arm clear of collisions all the way; else None."""
        return self._free_hand_path(start, self.line_follower(start, pose, self.tcp_step_limit(acceleration)))

    def arcs_round_base(self, start: np.ndarray, pose: sapien.Pose, acceleration: float = 1.0) -> list[np.ndarray]:
        """Where the oracle moves in straight lines (``moves_in_straight_lines``), the arm joint targets that take the hand
        round the arm's base to ``pose``, each way round and with the hand turning evenly from its orientation to the
        pose's or carried round with the sweep as well, that the controller follows with the arm clear of collisions
        all the way, the shorter first; as fast as ``paced`` lets a motion at ``acceleration``. For a hand that must go
        from one side of the base to the other, where the straight line between would pass over the base."""
        if not self.moves_in_straight_lines or self.arc_follower is None:
            return []
        limit = self.tcp_step_limit(acceleration)
        arcs = [self.arc_follower(start, pose, limit, way, carried) for way in (1, -1) for carried in (False, True)]
        paths = [self._free_hand_path(start, arc) for arc in arcs]
        return sorted((path for path in paths if path is not None), key=len)

    def _free_hand_path(self, start: np.ndarray, path: Optional[np.ndarray]) -> Optional[np.ndarray]:
        """``path`` (arm joint targets from ``start``, one per control step) if the arm keeps clear of collisions between
        each and the next, else None (None stays None)."""
        if path is None:
            return None
        waypoints = np.concatenate([np.asarray(start)[None], path])
        return path if all(self.path_is_free(a, b, samples=2) for a, b in zip(waypoints, waypoints[1:])) else None

    @property
    def moves_in_straight_lines(self) -> bool:
        """Whether the oracle acts through a TCP controller and moves the hand in straight lines there
        (``straight_lines_under_tcp_control``)."""
        return self.line_follower is not None and self.straight_lines_under_tcp_control

    def follow(self, path: np.ndarray, what: str) -> Iterator[np.ndarray]:
        """Send ``path`` (arm joint targets, one per control step) as it is."""
        self.phase = what
        yield from self._follow(path, retime=False)

    def joint_move(self, goal: np.ndarray, what: str, acceleration: float = 1.0) -> Iterator[np.ndarray]:
        """Straight joint-space move to ``goal`` (arm joints), time-optimally parameterised (at ``acceleration``
        times the usual joint accelerations)."""
        self.phase = what
        start = self.arm_qpos()
        if not self.path_is_free(start, goal):
            raise PlanningFailed(f"the joint-space move to the {what} pose collides")
        yield from self._follow(self._joint_move_path(start, goal, acceleration), retime=False)

    def _joint_move_path(self, start: np.ndarray, goal: np.ndarray, acceleration: float) -> np.ndarray:
        """The joint targets ``joint_move`` sends, one per control step, for its move from ``start`` to ``goal``."""
        with self._speed(1.0, acceleration):
            return self.paced(self._timed_path(start, goal), start, acceleration)

    def joint_move_steps(self, start: np.ndarray, goal: np.ndarray, acceleration: float = 1.0) -> int:
        """How many control steps ``joint_move(goal)`` from ``start`` takes."""
        return len(self._joint_move_path(start, goal, acceleration))

    def joint_move_end(self, start: np.ndarray, goal: np.ndarray, acceleration: float = 1.0) -> Optional[np.ndarray]:
        """Where ``joint_move(goal)`` from ``start`` leaves the arm: ``goal``, unless the oracle acts through a TCP
        controller (``arm_follower``), whose IK takes the hand along the same poses but may end with the elbow and wrist
        elsewhere (traced on Solar Panel Assembly, Moon, seed 0: the swing over the first socket, planned to end with the
        wrist's joint at 3.11 rad, 0.64 from its upper limit, ended at the limit, and the line-up from there knocked the
        peg out of the fingers); None where the controller would stall short of it."""
        if self.arm_follower is None:
            return goal
        return self.arm_follower(start, self._joint_move_path(start, goal, acceleration))

    def straight_move_duration(self, start: np.ndarray, goal: np.ndarray) -> float:
        """Seconds the straight joint-space move from ``start`` to ``goal`` takes at the least: its slowest joint
        speeding up at the planner's acceleration limit to its velocity limit and slowing down again (a lower bound
        on what ``_timed_path`` gives, at a fraction of its cost)."""
        distance = np.abs(np.asarray(goal) - np.asarray(start))
        velocity, acceleration = self.solver.planner.joint_vel_limits[: len(distance)], self.solver.planner.joint_acc_limits[: len(distance)]
        cruising = distance > velocity**2 / acceleration
        seconds = np.where(cruising, distance / velocity + velocity / acceleration, 2.0 * np.sqrt(distance / acceleration))
        return float(seconds.max())

    def _timed_path(self, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
        if np.abs(goal - start).max() < 1e-4:  # already there (the parameterisation needs a path to follow)
            return goal[None]
        _, positions, _, _, _ = self.solver.planner.TOPP(np.stack([start, goal]), step=self.env.control_timestep)
        return np.concatenate([positions, goal[None]])

    def ik_solutions(self, pose: sapien.Pose, near: Optional[np.ndarray] = None) -> list[np.ndarray]:
        """Collision-free IK solutions from a fixed set of starts (deterministic), nearest to ``near`` (the current
        arm joints by default) first."""
        self._plan_from_the_base_now()
        self._plan_with_the_fingers_now()
        planner = self.solver.planner
        target = self.solver.base_pose.inv() * pose
        goal = np.concatenate([target.p, target.q])
        start = self.arm_qpos() if near is None else np.asarray(near)
        dof = len(start)
        solutions = []
        for seed in [start, *_ik_starts(planner, dof)]:
            status, found = planner.IK(goal, planner.pad_qpos(seed.copy()), n_init_qpos=1)
            if status == "Success":
                solutions.append(found[0][:dof])
        return sorted(solutions, key=lambda q: float(np.abs(q - start).max()))

    def screw_is_feasible(self, start: np.ndarray, pose: sapien.Pose) -> bool:
        return self._screw_path(start, pose) is not None

    def _screw_path(self, start: np.ndarray, pose: sapien.Pose) -> Optional[np.ndarray]:
        """Joint positions of a collision-free screw motion of the TCP from ``start`` to ``pose``, if any."""
        self._plan_from_the_base_now()
        self._plan_with_the_fingers_now()
        planner = self.solver.planner
        try:
            result = planner.plan_screw(
                np.concatenate([pose.p, pose.q]),
                planner.pad_qpos(start.copy()),
                qpos_step=self.screw_step,
                time_step=self.env.control_timestep,
                use_point_cloud=self.solver.use_point_cloud,
            )
        except RuntimeError:  # mplib cannot time-parameterise a path of (almost) zero length: already there
            return np.asarray(start)[None]
        return result["position"] if result["status"] == "Success" else None

    def screw_limit_margin(self, start: np.ndarray, pose: sapien.Pose) -> Optional[float]:
        """The least joint-limit margin (rad, ``joint_limit_margin``) along the screw motion from ``start`` to
        ``pose``, or None if there is no such motion."""
        positions = self._screw_path(start, pose)
        if positions is None:
            return None
        return min(self.joint_limit_margin(qpos[: len(start)]) for qpos in positions)

    def tcp_path(self, start: np.ndarray, goal: np.ndarray, samples: int = 20) -> tuple[np.ndarray, list[Rotation]]:
        """TCP positions (world frame) and orientations along the straight joint-space move from ``start`` to
        ``goal``."""
        return self._tcp_poses([start + t * (goal - start) for t in np.linspace(0.0, 1.0, samples)])

    def _tcp_poses(self, joint_positions) -> tuple[np.ndarray, list[Rotation]]:
        planner = self.solver.planner
        model, tcp = planner.pinocchio_model, planner.move_group_link_id
        positions, rotations = [], []
        for qpos in joint_positions:
            model.compute_forward_kinematics(planner.pad_qpos(qpos))
            pose = self.solver.base_pose * sapien.Pose(*np.split(model.get_link_pose(tcp), [3]))
            positions.append(pose.p)
            rotations.append(Rotation.from_quat(np.roll(pose.q, -1)))  # wxyz -> xyzw
        return np.asarray(positions), rotations

    def steps_along(self, positions: np.ndarray, rotations: list[Rotation], pace: Optional[tuple[float, float]] = None) -> float:
        """About how many control steps a TCP path takes at ``pace`` (``tcp_pace`` by default)."""
        return float(self._paces(positions, rotations, pace).sum())

    def _paces(self, positions: np.ndarray, rotations: list[Rotation], pace: Optional[tuple[float, float]] = None) -> np.ndarray:
        """Each segment of a TCP path in steps at ``pace`` (``tcp_pace`` by default; its move or its turn, whichever
        is further)."""
        metres, radians = pace or self.tcp_pace
        moves = np.linalg.norm(np.diff(positions, axis=0), axis=1) / metres
        turns = np.array([(a.inv() * b).magnitude() for a, b in zip(rotations, rotations[1:])]) / radians
        return np.maximum(moves, turns)

    def joint_limit_margin(self, qpos: np.ndarray) -> float:
        """How far (rad) the arm joints at ``qpos`` are from their nearest limit."""
        limits = np.asarray(self.solver.planner.joint_limits)[: len(qpos)]
        return float(np.min(np.minimum(qpos - limits[:, 0], limits[:, 1] - qpos)))

    def _path_samples(self, start: np.ndarray, goal: np.ndarray, samples: int) -> int:
        """How many points of a straight joint move to check: ``samples``, or one every ``path_check_step`` rad."""
        if self.path_check_step is None:
            return samples
        return max(samples, int(np.ceil(np.abs(np.asarray(goal) - np.asarray(start)).max() / self.path_check_step)) + 1)

    def path_is_free(self, start: np.ndarray, goal: np.ndarray, samples: int = 20) -> bool:
        samples = self._path_samples(start, goal, samples)
        self._plan_with_the_fingers_now()
        planner = self.solver.planner
        for t in np.linspace(0.0, 1.0, samples):
            qpos = planner.pad_qpos(start + t * (goal - start))
            collides = planner.check_for_env_collision(planner.robot, qpos, with_point_cloud=self.solver.use_point_cloud)
            if collides or planner.check_for_self_collision(planner.robot, qpos):
                return False
        return True

    def path_keeps_held_box_clear(self, start: np.ndarray, goal: np.ndarray, box_in_tcp: np.ndarray, half_extents: np.ndarray, samples: int = 20) -> bool:
        """Whether a box held in the hand (``box_held_in_hand``: its 4x4 pose in the TCP frame and its half extents) stays clear
        of the planner's obstacle points in use along the straight joint move from ``start`` to ``goal``.
        (mplib's attached objects would do this, but mplib 0.1.1 places them as if the arm's base stood at the origin.)"""
        obstacles = self._obstacles_in_use
        for position, rotation in zip(*self.tcp_path(start, goal, self._path_samples(start, goal, samples))):
            box = np.eye(4)
            box[:3, :3], box[:3, 3] = rotation.as_matrix(), position
            box = box @ box_in_tcp
            in_box_frame = (obstacles - box[:3, 3]) @ box[:3, :3]
            if np.all(np.abs(in_box_frame) <= half_extents, axis=1).any():
                return False
        return True

    def servo(
        self, target: Callable[[int], sapien.Pose], steps: int, what: str, until: Optional[Callable[[int], bool]] = None, far_solutions_after: Optional[int] = None
    ) -> Iterator[np.ndarray]:
        """Closed-loop Cartesian servo: at every step, the TCP pose ``target(step)`` (recomputed from the scene as
        it is now), solved by IK from the current joints and sent as the joint target. Where a step's pose has no
        solution (e.g. pressing past a stop), or whose solution is on another branch of the arm's inverse kinematics
        (a joint more than ``SERVO_JOINT_STEP`` away), the previous target is held; given ``far_solutions_after``, once
        it has been held that many steps in a row (across calls), the arm steps toward the nearest other solution
        instead (``_step_to_far_solution``). It runs
        ``steps`` steps, or, given ``until``, ends before the first step for which ``until(step)`` holds (checked on
        the scene as it is then)."""
        self.phase = what
        planner = self.solver.planner
        command = self.hold_action()
        for step in range(steps):
            if until is not None and until(step):
                return
            self._plan_from_the_base_now()
            self._plan_with_the_fingers_now()
            pose = target(step)
            goal = self.solver.base_pose.inv() * pose
            now = self.arm_qpos()
            status, solutions = planner.IK(np.concatenate([goal.p, goal.q]), planner.pad_qpos(now), n_init_qpos=1)
            if status == "Success" and np.abs(solutions[0][: len(now)] - now).max() <= SERVO_JOINT_STEP:
                command = np.hstack([solutions[0][: len(now)], self.gripper]).astype(np.float32)
                self.servo_held_steps = 0
            else:
                self.servo_held_steps += 1
                toward = self._step_to_far_solution(pose, now) if far_solutions_after is not None and self.servo_held_steps > far_solutions_after else None
                if toward is not None:
                    command = np.hstack([toward, self.gripper]).astype(np.float32)
            yield command

    def _step_to_far_solution(self, pose: sapien.Pose, now: np.ndarray) -> Optional[np.ndarray]:
        """Where the servo finds no solution of ``pose`` near the joints ``now`` (the wrist at its limit, or the
        nearest solution on another branch): a step toward the nearest collision-free solution of ``pose`` or of the
        same grasp half a turn about the approach axis (``wrist_turned``: the fingers are alike), every joint at most
        ``SERVO_JOINT_STEP`` and the hand at most ``FAR_STEP_PACE``, where the joints' straight way there is free;
        None where there is none."""
        for solution in sorted((q for grasp in (pose, wrist_turned(pose)) for q in self.ik_solutions(grasp, near=now)), key=lambda q: float(np.abs(q - now).max())):
            if self.path_is_free(now, solution):
                step = np.clip(solution - now, -SERVO_JOINT_STEP, SERVO_JOINT_STEP)
                paced = np.concatenate([[0.0], np.cumsum(self._paces(*self.tcp_path(now, now + step), pace=FAR_STEP_PACE))])
                return now + step * np.interp(1.0, paced, np.linspace(0.0, 1.0, len(paced)))
        return None

    def wait_for_success(self, most_steps: int, stable_steps: int = 3) -> Iterator[np.ndarray]:
        """Hold still until the task has reported success for ``stable_steps`` steps in a row (e.g. a released
        object has come to rest), at most ``most_steps`` steps."""
        self.phase = "waiting for success"
        streak = 0
        for _ in range(most_steps):
            streak = streak + 1 if bool(self.env.evaluate()["success"][0]) else 0
            if streak >= stable_steps:
                return
            yield self.hold_action()

    def first_reachable(self, poses: list[sapien.Pose], what: str, **motion) -> Iterator[np.ndarray]:
        """``screw_to`` the first of ``poses`` the arm can move to from where it is (e.g. a retreat straight up, as far
        as the arm goes); PlanningFailed if it can reach none."""
        start = self.arm_qpos()
        for pose in poses:
            if self.motion_end(start, pose, motion.get("acceleration", 1.0)) is not None:
                yield from self.screw_to(pose, what, **motion)
                return
        raise PlanningFailed(f"no motion to the {what} pose")

    def retreat_up(self, distances: tuple[float, ...]) -> Iterator[np.ndarray]:
        """Up from where the hand is, to the first of ``distances`` (longest first) the arm can move to; where the oracle
        ``retreats_straight_up``, to the first it can reach in a straight line (``straight_motion_exists``) if any."""
        start, poses = self.arm_qpos(), [raised(self.tcp_pose(), d) for d in distances]
        if self.retreats_straight_up:
            straight = next((pose for pose in poses if self.straight_motion_exists(start, pose)), None)
            if straight is not None:
                # screw_to takes the straight motion found (``_motion_path`` tries those first): no need to plan it again
                yield from self.screw_to(straight, "retreat")
                return
        yield from self.first_reachable(poses, "retreat")

    def straight_motion_exists(self, start: np.ndarray, pose: sapien.Pose) -> bool:
        """Whether ``screw_to(pose)`` from ``start`` takes the hand in a straight line: mplib's screw motion, or the TCP
        controller's line where the oracle moves in straight lines (``_motion_path`` takes the first of these there is)."""
        return self.straight_motion_end(start, pose) is not None

    def straight_motion_end(self, start: np.ndarray, pose: sapien.Pose) -> Optional[np.ndarray]:
        """Where ``screw_to(pose)`` from ``start`` leaves the arm if it takes the hand in a straight line (as
        ``straight_motion_exists``), else None."""
        path = self._screw_path(start, pose)
        if path is None:
            path = self.straight_line_path(start, pose)
        return None if path is None else self._followed_end(start, path)

    def wait_for_grasp(self, actor, what: str, most_steps: int = 8, closing_steps: int = 40) -> Iterator[np.ndarray]:
        """Hold the closed gripper until it grasps ``actor`` (the fingers' forces build up over a few steps);
        GraspMissed if it has not within ``most_steps``, or, while the fingers are still closing, within
        ``closing_steps``: fingers that drag on the ground beside a lying peg close on it a millimetre a step (traced on
        Solar Panel Assembly in ``pd_ee_delta_pose``, Moon, seed 6014: still 2 mm short of the peg after 14 steps);
        at once where the fingers have shut on nothing (``FINGERS_SHUT``), so that another grasp may be tried sooner."""
        self.phase = f"grasping {what}"
        before = self.finger_qpos()
        for step in range(closing_steps):
            if bool(self.env.is_grasping(actor)[0]):
                return
            now = self.finger_qpos()
            if np.all(now <= FINGERS_SHUT) or (step >= most_steps and np.abs(now - before).max() < FINGERS_STILL):
                break
            before = now
            yield self.hold_action()
        raise GraspMissed(f"the grasp missed {what}")

    def finger_qpos(self) -> np.ndarray:
        """The gripper's finger joints now (m)."""
        return self.env.agent.robot.get_qpos()[0, len(self.arm_qpos()) :].cpu().numpy()

    def set_gripper(self, state: float, steps: int = 6) -> Iterator[np.ndarray]:
        self.phase = "closing the gripper" if state < self.gripper else "opening the gripper"
        self.gripper = state
        yield from self._follow(np.repeat(self.arm_qpos()[None], steps, axis=0), retime=False)

    def open_gently(self, steps: int = 12) -> Iterator[np.ndarray]:
        """Open the gripper a little at a time, so that a released object is not flicked (in zero gravity it
        would keep the spin)."""
        self.phase = "letting go"
        arm = self.hold_action()[:-1]
        for gripper in np.linspace(self.gripper, GRIPPER_OPEN, steps + 1)[1:]:
            self.gripper = float(gripper)
            yield np.hstack([arm, self.gripper]).astype(np.float32)

    def _follow(self, positions: np.ndarray, retime: bool = True) -> Iterator[np.ndarray]:
        if retime:
            positions = self.paced(positions)
        for qpos in positions:
            yield np.hstack([qpos, self.gripper]).astype(np.float32)

    def paced(self, positions: np.ndarray, start: Optional[np.ndarray] = None, acceleration: float = 1.0) -> np.ndarray:
        """``positions`` (a joint path from ``start``, the arm's joints now by default, one target per control step, planned
        at ``acceleration`` times the usual joint accelerations) as the oracle sends them: retimed to ``tcp_pace`` where
        set, else slowed where the TCP would outrun ``tcp_speed_limit`` (``free_space_translation_scale`` times its
        translation for a motion at more than the usual accelerations)."""
        start = self.arm_qpos() if start is None else np.asarray(start)
        if self.tcp_pace is not None:
            return self._retimed_to_tcp_pace(positions, start)
        if self.tcp_speed_limit is not None:
            return self._slowed_to_speed_limit(positions, start, self.tcp_step_limit(acceleration))
        return positions

    def tcp_step_limit(self, acceleration: float = 1.0) -> tuple[float, float]:
        """(metres, radians): how far the TCP may move and turn in a control step in a motion planned at
        ``acceleration`` times the usual joint accelerations: ``tcp_speed_limit``, its translation
        ``free_space_translation_scale`` times farther for a brisk (free-space) motion."""
        metres, radians = self.tcp_speed_limit
        return (metres * self.free_space_translation_scale if acceleration > 1.0 else metres), radians

    def _slowed_to_speed_limit(self, positions: np.ndarray, start: np.ndarray, limit: tuple[float, float]) -> np.ndarray:
        """``positions`` (from ``start``) resampled along the same path with every step
        that would move the TCP farther than ``limit`` (metres, radians) stretched to as many steps as the limit needs (the
        other steps keep their timing)."""
        path = np.concatenate([start[None], positions])
        durations = np.maximum(1.0, self._paces(*self._tcp_poses(path), pace=limit))
        times = np.concatenate([[0.0], np.cumsum(durations)])
        if times[-1] <= len(positions) + 1e-9:  # nothing to slow
            return positions
        steps = np.linspace(0.0, times[-1], int(np.ceil(times[-1] - 1e-9)) + 1)[1:]
        return np.stack([np.interp(steps, times, path[:, joint]) for joint in range(path.shape[1])], axis=1)

    def _retimed_to_tcp_pace(self, positions: np.ndarray, start: np.ndarray) -> np.ndarray:
        """``positions`` (a joint path from ``start``, one target per control step)
        resampled along the same path so that the TCP moves at ``tcp_pace``, reaching it in ``TCP_RAMP_STEPS`` steps and
        slowing down as long at the end (a jolt would fling a held object)."""
        path = np.concatenate([start[None], positions])
        progress = np.concatenate([[0.0], np.cumsum(self._paces(*self._tcp_poses(path)))])
        if progress[-1] < 1e-6:
            return positions
        steps = np.cumsum(_trapezoid(progress[-1], TCP_RAMP_STEPS))
        return np.stack([np.interp(steps, progress, path[:, joint]) for joint in range(path.shape[1])], axis=1)


def _trapezoid(distance: float, ramp_steps: int) -> np.ndarray:
    """Per-step advances (at most 1) covering ``distance``: up by 1 / ramp_steps a step, full pace, and down."""
    half: list[float] = []
    while sum(half) < distance / 2:
        half.append(min(1.0, (len(half) + 1) / ramp_steps))
    advances = np.array(half + half[::-1])
    return advances * distance / advances.sum()


def backed_off(pose: sapien.Pose, distance: float) -> sapien.Pose:
    """``pose`` moved back along its approach direction (TCP z)."""
    return pose * sapien.Pose([0.0, 0.0, -distance])


def raised(pose: sapien.Pose, height: float) -> sapien.Pose:
    """``pose`` moved straight up by ``height`` (straight out of a vertical socket, whatever the hand's tilt)."""
    return sapien.Pose(pose.p + np.array([0.0, 0.0, height]), pose.q)


def at_height(pose: sapien.Pose, height: float) -> sapien.Pose:
    """``pose`` moved vertically to ``height`` (world z)."""
    return sapien.Pose([pose.p[0], pose.p[1], height], pose.q)


def tcp_pose_with_axes(point: np.ndarray, approach: np.ndarray, closing: np.ndarray) -> sapien.Pose:
    """The TCP pose at ``point`` with its approach (z) and closing (y) axes (``closing`` made unit; it must be square
    to ``approach``)."""
    closing = closing / np.linalg.norm(closing)
    frame = np.eye(4)
    frame[:3, :3] = np.stack([np.cross(closing, approach), closing, approach], axis=1)
    frame[:3, 3] = point
    return sapien.Pose(frame)


def wrist_turned(pose: sapien.Pose) -> sapien.Pose:
    """The hand at ``pose`` turned half a turn about its approach axis: the same grip, its fingers swapped."""
    return pose * sapien.Pose(q=HALF_TURN_ABOUT_APPROACH)


def turn_between(quaternion: np.ndarray, other: np.ndarray) -> float:
    """The angle (rad) of the rotation from one wxyz quaternion's orientation to the other's."""
    return float(2.0 * np.arccos(min(1.0, abs(float(np.dot(quaternion, other))))))


def poses_within(pose: tuple[np.ndarray, np.ndarray], other: tuple[np.ndarray, np.ndarray], tolerance: tuple[float, float]) -> bool:
    """Whether two (position, wxyz quaternion) poses are within ``tolerance`` (metres, radians) of each other."""
    return bool(np.linalg.norm(np.asarray(pose[0]) - np.asarray(other[0])) <= tolerance[0] and turn_between(pose[1], other[1]) <= tolerance[1])


def _ik_starts(planner, dof: int, count: int = 24) -> np.ndarray:
    """Fixed pseudo-random start configurations within the joint limits (the same in every process)."""
    limits = np.asarray(planner.joint_limits)[:dof]
    return np.random.default_rng(0).uniform(limits[:, 0], limits[:, 1], size=(count, dof))


def box_held_in_hand(points_in_object: np.ndarray, object_pose: np.ndarray, hand_pose: np.ndarray, margin: float) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box of an object's points (``points_in_object``, in its own frame), grown by ``margin``, as a hand
    at ``hand_pose`` holds the object at ``object_pose`` (both world, 4 x 4): the box's pose in the TCP frame and its
    half extents (``Oracle.path_keeps_held_box_clear``)."""
    low, high = points_in_object.min(axis=0), points_in_object.max(axis=0)
    box_in_object = np.eye(4)
    box_in_object[:3, 3] = (low + high) / 2
    return np.linalg.inv(hand_pose) @ object_pose @ box_in_object, (high - low) / 2 + margin


def surface_points(asset, pose: np.ndarray = np.eye(4), margin: float = 0.0, spacing: float = POINT_SPACING) -> np.ndarray:
    """Obstacle points on an asset's collision parts, about ``spacing`` apart, placed at ``pose`` (world frame);
    with a ``margin``, the points stand that far out from the surface (the planner then keeps the arm about that
    far from it, given points no farther apart than the margin)."""
    points = _surface_points(asset, np.random.default_rng(0), margin, spacing)
    return points @ pose[:3, :3].T + pose[:3, 3]


def _surface_points(asset, rng: np.random.Generator, margin: float = 0.0, spacing: float = POINT_SPACING) -> np.ndarray:
    """Points on (or ``margin`` out from) the collision parts of an asset, in the asset's frame."""
    import trimesh

    samples = []
    for part in asset.collision_parts:
        count = max(SURFACE_POINTS_PER_PART, int(part.mesh.area / spacing**2))
        points, faces = trimesh.sample.sample_surface(part.mesh, count, seed=rng)
        samples.append(points + margin * part.mesh.face_normals[faces])
    return np.concatenate(samples)


def inflated_surface_points(asset, pose: np.ndarray = np.eye(4), margin: float = 0.01, spacing: float = 0.005) -> np.ndarray:
    """Obstacle points on each collision part of an asset grown by ``margin`` in every direction (its hull swept by a
    ball of that radius), about ``spacing`` apart, placed at ``pose`` (world frame). ``surface_points``' points pushed
    out along each face's normal leave the margin open along the part's edges, and a finger brushing a standing peg's
    top edge passes there (traced on Solar Panel Assembly, Moon, reference assets, seed 64005: the planned move to the
    second peg's pre-grasp pose ran a fingertip 6 mm from the first peg's axis, and knocked it out of its socket)."""
    import trimesh

    from mani_skill_space.procgen.asset import CollisionPart

    ball = trimesh.creation.icosphere(subdivisions=2).vertices * margin
    grown = tuple(CollisionPart(trimesh.convex.convex_hull((np.asarray(part.mesh.vertices)[:, None] + ball[None]).reshape(-1, 3))) for part in asset.collision_parts)
    return surface_points(dataclasses.replace(asset, collision_parts=grown), pose, spacing=spacing)


class _ServicerArmSolver(PandaArmMotionPlanningSolver):
    """ManiSkill's Panda planner for the arm on a free-flying servicer: it plans the arm alone (its own description,
    without the bus link) from the bus's pose (``Oracle._plan_from_the_base_now``)."""

    def setup_planner(self):
        import mplib

        from mani_skill_space.procgen.servicer import BUS_LINK

        arm = self.env_agent.arm_urdf_path
        planner = mplib.Planner(
            urdf=arm,
            srdf=arm.replace(".urdf", ".srdf"),
            user_link_names=[link.get_name() for link in self.robot.get_links() if link.get_name() != BUS_LINK],
            user_joint_names=[joint.get_name() for joint in self.robot.get_active_joints()],
            move_group=getattr(self, "MOVE_GROUP", "eef"),
        )
        # as ManiSkill's setup_planner
        planner.set_base_pose(np.hstack([self.base_pose.p, self.base_pose.q]))
        planner.joint_vel_limits = np.asarray(planner.joint_vel_limits) * self.joint_vel_limits
        planner.joint_acc_limits = np.asarray(planner.joint_acc_limits) * self.joint_acc_limits
        return planner


def standing_obstacle_points(mount) -> np.ndarray:
    """What the arm stands on, as obstacle points (world frame): the mount's surface above the ground (none where
    ``mount`` is None), and the surface it stands on (ground or the station's platform) as a grid a little below it,
    so that the fingers may touch it but no link is planned into it."""
    points = np.zeros((0, 3)) if mount is None else surface_points(mount)
    return np.concatenate([points[points[:, 2] > GROUND_MARGIN], _ground_points()])


def _ground_points() -> np.ndarray:
    """A grid of points GROUND_MARGIN under the ground around the arm."""
    axis = np.arange(-GROUND_REACH, GROUND_REACH + POINT_SPACING / 2, POINT_SPACING)
    x, y = np.meshgrid(axis, axis)
    keep = np.hypot(x, y) <= GROUND_REACH
    return np.stack([x[keep], y[keep], np.full(keep.sum(), -GROUND_MARGIN)], axis=1)


def open_finger_corners(env) -> np.ndarray:
    """Corners (k, 3) of the open fingers' collision boxes in the TCP frame (the gripper as it is at reset: open)."""
    return np.concatenate(finger_box_corners(env))


def finger_pad_rectangle(env) -> np.ndarray:
    """The open finger pads' inner faces as a rectangle in the TCP frame's (x, z) plane: ``[[x_min, z_min], [x_max,
    z_max]]`` (the fingers' collision box nearest the closing axis, the pad, of the gripper as it is at reset)."""
    corners = min(finger_box_corners(env), key=lambda box: np.abs(box[:, 1]).min())
    return np.stack([corners[:, [0, 2]].min(axis=0), corners[:, [0, 2]].max(axis=0)])


def finger_box_corners(env) -> list[np.ndarray]:
    """The corners (8, 3) of each of the fingers' collision boxes, in the TCP frame, with the gripper as it is now."""
    to_tcp = np.linalg.inv(env.agent.tcp.pose.sp.to_transformation_matrix())
    boxes = []
    for link in env.agent.robot.links:
        if "finger" not in link.name:
            continue
        entity = link._objs[0].entity
        for shape in entity.find_component_by_type(sapien.physx.PhysxRigidBaseComponent).get_collision_shapes():
            box = np.array(list(itertools.product(*[(-h, h) for h in shape.half_size])))
            frame = to_tcp @ (entity.pose * shape.get_local_pose()).to_transformation_matrix()
            boxes.append(box @ frame[:3, :3].T + frame[:3, 3])
    return boxes


def pad_overlap(hand: sapien.Pose, points: np.ndarray, pad: np.ndarray, gap: Optional[float] = None) -> float:
    """The share of a finger pad's face (``pad``, as ``finger_pad_rectangle`` gives it) that closes on the convex
    object whose vertices are ``points`` (k, 3, world) with the hand at ``hand``: the overlap of the pad with the
    object's silhouette seen along the closing axis (only of its part within ``gap`` of the hand's middle across
    the fingers, where given: the part between the open fingers). Near 0 the fingers close on an edge or beside the
    object and flick it away; near 1 they hold it over their whole face."""
    from scipy.spatial import ConvexHull, QhullError

    from mani_skill_space.procgen.polytope import clip

    local = (points - hand.p) @ hand.to_transformation_matrix()[:3, :3]
    if gap is not None:
        local = clip(clip(local, np.array([0.0, 1.0, 0.0]), gap), np.array([0.0, -1.0, 0.0]), gap)
    silhouette = local[:, [0, 2]]
    for axis in (0, 1):
        silhouette = clip(silhouette, -np.eye(2)[axis], -pad[0][axis])
        silhouette = clip(silhouette, np.eye(2)[axis], pad[1][axis])
    try:
        area = ConvexHull(silhouette).volume if len(silhouette) >= 3 else 0.0
    except QhullError:  # a flat overlap covers no area
        area = 0.0
    return float(area / np.prod(pad[1] - pad[0]))


def collision_vertices(actor) -> np.ndarray:
    """World positions (k, 3) of the vertices of an actor's (first env's) convex collision shapes."""
    return np.concatenate(collision_part_vertices(actor))


def collision_part_vertices(actor) -> list[np.ndarray]:
    """World positions of the vertices of each of an actor's (first env's) convex collision shapes."""
    entity = actor._objs[0]
    parts = []
    for shape in entity.find_component_by_type(sapien.physx.PhysxRigidBaseComponent).get_collision_shapes():
        frame = (entity.pose * shape.get_local_pose()).to_transformation_matrix()
        parts.append((shape.get_vertices() * shape.get_scale()) @ frame[:3, :3].T + frame[:3, 3])
    return parts


def lowest_point(actor) -> float:
    """World height of the lowest vertex of an actor's (first env's) convex collision shapes."""
    return float(collision_vertices(actor)[:, 2].min())


LOWEST_GRASP_HEIGHT = 0.012
"""The lowest (m) a grasp from above goes (``top_down_grasp_pose``): the fingertips stay clear of the ground."""


def top_down_grasp_pose(env, actor, finger_length: float = 0.025) -> sapien.Pose:
    """A vertical grasp of ``actor`` across the shortest horizontal side of its oriented bounding box, no lower than
    ``LOWEST_GRASP_HEIGHT``."""
    from mani_skill.examples.motionplanning.base_motionplanner.utils import compute_grasp_info_by_obb, get_actor_obb

    obb = get_actor_obb(actor)
    approaching = np.array([0.0, 0.0, -1.0])
    target_closing = env.agent.tcp.pose.to_transformation_matrix()[0, :3, 1].cpu().numpy()
    info = compute_grasp_info_by_obb(obb, approaching=approaching, target_closing=target_closing, depth=finger_length)
    centre = np.asarray(obb.primitive.transform)[:3, 3]
    grasp = env.agent.build_grasp_pose(approaching, info["closing"], centre)
    return sapien.Pose([grasp.p[0], grasp.p[1], max(grasp.p[2], LOWEST_GRASP_HEIGHT)], grasp.q)
