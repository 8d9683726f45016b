"""Oracle for SolarPanelAssembly-v1.

Chains the shared peg insertion (``oracles.insertion``) four times (the farther, short sockets first, so that the arm never reaches
over an inserted peg to get to a socket), letting go of each peg and backing away from it before the next.
Then it takes the panel's grasp bar from above, lifts the panel straight up, swings it over the target with
its receptacles above the pegs' tops, lowers it onto them (re-measuring the panel in the hand on the way, as
for a peg) and lets go.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np
import sapien

from mani_skill_space.envs.solar_panel_assembly import FILL_ORDER
from mani_skill_space.oracles.base import FINE_SCREW_STEP, GRIPPER_CLOSED, Oracle, PlanningFailed, backed_off, box_held_in_hand, raised, surface_points
from mani_skill_space.oracles.insertion import SETTLE_STEPS, InsertionSettings, PegInserter, PegTarget, other_pegs, stayed_in

RETREAT_DISTANCE = 0.2
"""After letting go of a peg (or the panel) the hand goes straight up this far (backing out along a tilted
approach would drag a long peg over), well clear of the pegs' tops before it moves sideways: the planner's
point-cloud checks miss the open fingers brushing a thin peg's top."""
RETREAT_DISTANCES = (RETREAT_DISTANCE, 0.12, 0.06)
"""Where the arm cannot go the whole way up, it retreats as far as it can of these (``Oracle.retreat_up``)."""
PEG_LIFT_HEIGHT = 0.45
"""The TCP's height while swinging a peg over its socket: a long peg hanging from the hand clears the pegs
already standing (their tops at 0.28 m; the planner does not know about the peg in the hand)."""
PANEL_PRE_GRASP = 0.1
PANEL_PRE_GRASPS = (PANEL_PRE_GRASP, 0.06)
PANEL_LEVEL_ACROSS = 0.5
"""The bar's across direction must be at least this level (horizontal length of the unit vector) to be taken
from above."""
PANEL_LIFTS = (0.3, 0.2, 0.12)
"""How far (m) the panel goes straight up off the deck before swinging round: the first height a straight screw
motion reaches (a joint-space move there would swing the panel, which the planner does not see, through the
pegs already standing)."""
PANEL_SERVO_LIFT_STEP = 0.015
FREE_SPACE_ACCELERATION = 2.0
"""Joint accelerations, as a multiple of the usual ones, of the motions of an empty hand to its next grasp and of
the panel's swing high over the pegs: four pegs and a panel in 50 s. (Not while a peg is in the hand, where a
brisker swing turns it between the fingers, nor right after letting go of one.)"""
PLACE_GAP = 0.05
"""The panel is lined up this far above its seat (its receptacles clear of the pegs' tops) before going down."""
SWING_GAPS = (0.2, 0.12, PLACE_GAP)
"""The panel is swung round to this far above its seat (the first the arm reaches), then goes straight down to
PLACE_GAP: the planner does not see the panel in the hand, and a swing that ends low would sweep it through the
pegs' tops."""
HELD_PANEL_MARGIN = 0.02
"""How far (m) the panel's swing round keeps its bounding box from the pegs standing, the posts and the mount."""
PLACE_STEP = 0.004
PLACE_PRESS = 0.004


PEG_INSERTION = InsertionSettings(
    lift_height=PEG_LIFT_HEIGHT, relax_steps=6, insert_attempts=2, insert_step=0.004, refine_passes=1, pre_grasp_acceleration=FREE_SPACE_ACCELERATION,
    push_margin_under_tcp_control=True, carry_acceleration_under_tcp_control=FREE_SPACE_ACCELERATION, swing_keeps_held_peg_clear=True,
)
"""Four pegs and a panel in 50 s: a little brisker than Peg-in-Hole's single peg; the push eases off before
letting go (in orbit a peg let go while pressed into its socket springs back out of it), and a jammed push is
tried again. In ``pd_ee_delta_pose`` too, pushes clear of the joint limits come first: a stalled push leaves a peg
unseated and ends the plan (Moon, reference assets, seeds 0-7: every episode filled three sockets, against a mean
of 2.6 without the margin). The joint-space swing over a socket keeps the held peg clear of the obstacles
(``swing_keeps_held_peg_clear``): on Earth, procedural, tuning seed 64064, a swing that dipped the hand to 0.2 m struck
the peg on the arm's mount and turned it 40 degrees in the grip."""


class SolarPanelOracle(Oracle):
    screw_step = FINE_SCREW_STEP
    path_check_step = 0.02
    """Inserted pegs are thin and stand up high: a check at 20 points of a long swing can step over one."""
    via_height = PEG_LIFT_HEIGHT
    """Where neither mplib's screw nor the hand's straight line gets there, the empty hand may go over the standing pegs
    at the height a peg is carried at (``Oracle.over_the_top_path``): traced on procedural seed 6021 in
    ``pd_ee_delta_pose``, the joint-space move to the third peg's pre-grasp pose took 75 steps and 1.5 m of travel for
    0.7 m and left the arm where the fourth peg's grasp had no motion; over the top it takes 66 steps and the episode
    assembles."""
    straight_lines_under_tcp_control = True
    """In ``pd_ee_delta_pose`` the four pegs and the panel fit the 1000 steps only so (Moon, reference assets, seeds
    6000-6019: 4 of 20 assemblies, mean stage 6.35 of 8, against none and 3.25 with joint-space swings; with the
    brisker free-space motions 10 of 20, and with the arcs round the arm's base 19 of 20, mean stage 7.9)."""
    quicker_lines_under_tcp_control = True
    """And the hand's straight line instead of a screw motion wherever the line is quicker: the successful episodes end
    54-66 steps sooner on average (Moon, ``oracle_control_modes_solar`` 855 -> 789, procedural seeds 6000-6039 885 ->
    831), and 19 of 20 and 32 of 40 assemble, against 19 and 31."""
    free_space_translation_scale = 1.5
    """In ``pd_ee_delta_pose`` the empty hand's moves to its next grasp and the panel's swing round the arm's base
    (those at ``FREE_SPACE_ACCELERATION``) move the TCP at half the controller's translation limit, about as fast as the
    hand goes, instead of a third: the panel's swing and pre-grasp were where the time ran out (Moon, reference assets,
    tuning seeds 70000-70011: 7 of 12 assemblies, mean stage 7.25, against 3 and 6.75)."""

    def plan(self, env) -> Iterator[np.ndarray]:
        inserter = PegInserter(self, PEG_INSERTION)
        for socket in FILL_ORDER:
            target = PegTarget.of(env, env.pegs[socket], socket)
            self.make_solver(env, obstacles=self._obstacles(env, exclude_peg=socket))
            yield from inserter.insert(target)
            yield from self.open_gently(8)
            yield from self.retreat_up(RETREAT_DISTANCES)
            # let go, a peg may lean in its socket's clearance (or, in orbit, drift to a lean): the panel's
            # funnels right it; only a peg that has come out is a failure
            if not stayed_in(env, socket):
                raise PlanningFailed(f"peg {socket} did not stay in its socket")
        self.make_solver(env, obstacles=self._obstacles(env))
        yield from self.place_panel(env)
        yield from self.wait_for_success(20)

    def _obstacles(self, env, exclude_peg: int = -1) -> np.ndarray:
        """The socket posts, the other pegs where they are now (those already standing in their sockets with a
        margin) and, while the pegs go in, the panel where it is now, as the planner's obstacle points (the
        insertion leaves out the keep-out around its socket's axis while it lowers a peg in)."""
        base = np.eye(4)
        base[:3, 3] = env.socket_base.pose.p[0].cpu().numpy()
        points = [surface_points(env.socket_assets[0], base)]
        standing = FILL_ORDER[: FILL_ORDER.index(exclude_peg)] if exclude_peg >= 0 else FILL_ORDER
        points.append(other_pegs(env.pegs, env.peg_assets[0], exclude_peg, standing))
        if exclude_peg >= 0:
            points.append(surface_points(env.panel_assets[0], env.panel.pose.sp.to_transformation_matrix()))
        return np.concatenate(points)

    # ------------------------------------------------------------------ panel
    def place_panel(self, env) -> Iterator[np.ndarray]:
        grasp = self._panel_grasp(env)
        yield from self.first_reachable([backed_off(grasp, d) for d in PANEL_PRE_GRASPS], "panel pre-grasp", acceleration=FREE_SPACE_ACCELERATION)
        yield from self.screw_to(grasp, "panel grasp", SETTLE_STEPS)
        yield from self.set_gripper(GRIPPER_CLOSED)
        yield from self.wait_for_grasp(env.panel, "the panel's bar")
        yield from self._lift_panel()

        yield from self._swing_over_target(env)
        for _ in range(2):
            yield from self.screw_to(self._tcp_for_seat(env, PLACE_GAP), "panel line-up", SETTLE_STEPS)
        steps = int(np.ceil((PLACE_GAP + PLACE_PRESS) / PLACE_STEP))
        height = lambda step: max(-PLACE_PRESS, PLACE_GAP - (step + 1) * PLACE_STEP)  # noqa: E731
        yield from self.servo(lambda step: self._tcp_for_seat(env, height(step)), steps + SETTLE_STEPS, "lower the panel")
        yield from self.open_gently(8)
        yield from self.retreat_up(RETREAT_DISTANCES)

    def _lift_panel(self) -> Iterator[np.ndarray]:
        """Straight up, as high as a screw motion goes (PANEL_LIFTS); failing all, by servoing the hand up the
        vertical line step by step (it stops where the arm can go no higher)."""
        for height in PANEL_LIFTS:
            path = self._screw_path(self.arm_qpos(), raised(self.tcp_pose(), height))
            if path is not None:
                yield from self._follow(path)
                return
        start, steps = self.tcp_pose(), int(np.ceil(PANEL_LIFTS[0] / PANEL_SERVO_LIFT_STEP))
        yield from self.servo(lambda step: raised(start, min(PANEL_LIFTS[0], (step + 1) * PANEL_SERVO_LIFT_STEP)), steps + SETTLE_STEPS, "panel lift")

    def _panel_grasp(self, env) -> sapien.Pose:
        """The hand straight down over the bar's centre, closing across it, whichever way round the arm reaches: the first
        way round from whose pre-grasp pose the hand comes straight down to the bar (``_comes_straight_down_to``), else
        the first the arm reaches at all. The panel is not among the planner's obstacles, and where there is no straight
        way down the joint-space move whirls the hand round into it (traced on Earth, procedural, tuning seed 64075: the
        pre-grasp pose left the wrist at its joint limit, the move down swung the hand 20 cm aside and back, and it
        knocked the panel 5 cm along the mount before the fingers closed)."""
        handle = env.panel_handle()[0].cpu().numpy().astype(np.float64)
        across = handle[:3, 0] * [1.0, 1.0, 0.0]  # level, even if the panel was knocked askew
        if np.linalg.norm(across) < PANEL_LEVEL_ACROSS:
            raise PlanningFailed("the panel's bar stands on end: there is no grasp from above")
        across /= np.linalg.norm(across)
        reached = []
        for sign in (1.0, -1.0):
            pose = env.agent.build_grasp_pose(np.array([0.0, 0.0, -1.0]), sign * across, handle[:3, 3])
            if self.ik_solutions(pose) and self.ik_solutions(backed_off(pose, PANEL_PRE_GRASP)):
                if self._comes_straight_down_to(pose):
                    return pose
                reached.append(pose)
        if reached:
            return reached[0]
        raise PlanningFailed("the arm cannot reach down to the panel's bar")

    def _comes_straight_down_to(self, grasp: sapien.Pose) -> bool:
        """Whether, from where the move to the panel's pre-grasp pose leaves the arm (the first of ``PANEL_PRE_GRASPS`` it
        reaches from where the arm is, as ``place_panel`` goes), the hand comes down to ``grasp`` in a straight line."""
        start = self.arm_qpos()
        for distance in PANEL_PRE_GRASPS:
            arm = self.motion_end(start, backed_off(grasp, distance), FREE_SPACE_ACCELERATION)
            if arm is not None:
                return self.straight_motion_exists(arm, grasp)
        return False

    def _swing_over_target(self, env) -> Iterator[np.ndarray]:
        """The panel swung high above its seat (the first of SWING_GAPS, either way round, that the arm reaches with the
        panel kept clear), by a straight joint move; where the oracle moves in straight lines, by the quickest of that
        and the hand's paths there, a straight line (``Oracle.straight_line_path``) or an arc round the arm's base
        (``Oracle.arcs_round_base``: the panel lies behind the base and its target in front, and from some grasps the
        joint move whirls the hand round for 120-130 steps)."""
        start = self.arm_qpos()
        panel_in_tcp, half_extents = self._held_panel_box(env)
        for gap in SWING_GAPS:
            moves = []  # (what to send: a hand path, or an arm goal for a joint move; in how many steps)
            for half_turns in (0, 1):
                pose = self._tcp_for_seat(env, gap, half_turns)
                hand_paths = [self.straight_line_path(start, pose, FREE_SPACE_ACCELERATION)] + self.arcs_round_base(start, pose, FREE_SPACE_ACCELERATION)
                moves += [(("path", path), len(path)) for path in hand_paths if path is not None and self._hand_path_keeps_held_box_clear(start, path, panel_in_tcp, half_extents)]
                arm = next((arm for arm in self.ik_solutions(pose) if self.path_is_free(start, arm) and self.path_keeps_held_box_clear(start, arm, panel_in_tcp, half_extents)), None)
                if arm is not None and not self.moves_in_straight_lines:  # the first joint move, as it comes
                    yield from self.joint_move(arm, "over the target", FREE_SPACE_ACCELERATION)
                    return
                if arm is not None:
                    moves.append((("joint", arm), len(self._joint_move_path(start, arm, FREE_SPACE_ACCELERATION))))
            if moves:
                (kind, move), _ = min(moves, key=lambda move: move[1])
                yield from self.follow(move, "over the target") if kind == "path" else self.joint_move(move, "over the target", FREE_SPACE_ACCELERATION)
                return
        raise PlanningFailed("no arm configuration holds the panel over its target")

    def _hand_path_keeps_held_box_clear(self, start: np.ndarray, path: np.ndarray, box_in_tcp: np.ndarray, half_extents: np.ndarray) -> bool:
        waypoints = np.concatenate([start[None], path])
        return all(self.path_keeps_held_box_clear(a, b, box_in_tcp, half_extents, samples=2) for a, b in zip(waypoints, waypoints[1:]))

    def _held_panel_box(self, env) -> tuple[np.ndarray, np.ndarray]:
        """The panel's bounding box (of its collision parts, grown by HELD_PANEL_MARGIN) as the hand holds it now: its
        pose in the TCP frame and its half extents. The planner knows nothing of the panel, and a joint-space swing
        that dips it sweeps it through the pegs' tops."""
        panel = env.panel.pose.sp.to_transformation_matrix()
        return box_held_in_hand(surface_points(env.panel_assets[0]), panel, self.tcp_pose().to_transformation_matrix(), HELD_PANEL_MARGIN)

    def _tcp_for_seat(self, env, height: float, half_turns: int = None) -> sapien.Pose:
        """The TCP pose that puts the panel's seat ``height`` above its target, given how the hand holds the panel
        now; the target turned by the half turn nearer the panel's heading unless ``half_turns`` says."""
        seat = env.panel_seat()[0].cpu().numpy().astype(np.float64)
        target = env.panel_target[0].cpu().numpy().astype(np.float64)
        if half_turns is None:
            half_turns = int(seat[:3, 0] @ target[:3, 0] < 0)
        if half_turns:
            target = target @ np.diag([-1.0, -1.0, 1.0, 1.0])
        goal = target.copy()
        goal[2, 3] += height
        seat_in_tcp = np.linalg.inv(self.tcp_pose().to_transformation_matrix()) @ seat
        return sapien.Pose(goal @ np.linalg.inv(seat_in_tcp))
