
import numpy as np
import sapien
import torch
from mani_skill.utils.geometry.rotation_conversions import quaternion_to_matrix
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.pose import Pose

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.envs.arm_reach import face_checks_with_the_arm
from mani_skill_space.envs.base import PENALTY_TERMS, SocketClearance, SpaceManipulationEnv
from mani_skill_space.envs.building import build_actor_per_env
from mani_skill_space.envs.insertion import (
    INSERTION_VALUE,
    PEG_DROP_CLEARANCE,
    PegInsertion,
    allow_insertable_faces,
    feasibility_record,
    hole_in_peg_end,
    insertion_inputs,
    insertion_terms,
    latch_force,
    lying_peg_orientation,
    peg_placement,
    pegs_latched_in_holes,
    redrawn_seed,
    seated_pairs,
)
from mani_skill_space.geometry import pose_error, pose_matrix, relative_pose, rotation_6d, rotation_matrix
from mani_skill_space.procgen.asset import Asset
from mani_skill_space.procgen.mounts import DECK_HEIGHT, make_rover, make_station
from mani_skill_space.procgen.solar_panel import (
    LONG_SOCKETS,
    RECEPTACLE_DEPTH,
    SEAT_HEIGHT,
    SOCKET_OFFSETS,
    check_socket_clearance,
    dataset_layout,
    make_panel,
    make_socket_base,
    make_solar_layout,
    make_solar_pegs,
    socket_frames,
)
from mani_skill_space.rewards import RewardTable, RewardTerm, band_distance

PANEL_TARGET_XY = (0.55, 0.0)
"""The panel's target centre (the reference's): the sockets sit around it."""
PANEL_START_XY = (-0.34, 0.0)
"""The panel lies on the rover's deck (or the station's platform) behind the arm, its long side across the
deck (this task's rover carries no cargo bin)."""
PANEL_START_JITTER = (0.01, 0.02, np.pi / 36)
PANEL_DROP_CLEARANCE = 0.001
PEG_REST_XY = ((0.34, 0.36), (0.34, -0.36), (0.34, 0.05), (0.34, -0.05))
"""Where each socket's peg lies (socket order: long, long, short, short): in front of the arm, the long pegs
outside the short ones."""
PEG_JITTER = 0.01
SEAT_DISTANCE_TOLERANCE = 0.01
SEAT_ANGLE_TOLERANCE = np.radians(5.0)
PANEL_LIFT_BAND = (0.03, 0.5)
SOCKET_COUNT = len(SOCKET_OFFSETS)
FILL_ORDER = (2, 3, 0, 1)
"""The order the sockets are best filled in: the farther (short) ones first, so that the hand never reaches over a
standing peg. The oracle's order, and the one the state observation's next peg follows."""

PEG_TERMS = insertion_terms(prefix="peg_")
"""Peg-in-Hole's terms, for the peg nearest to going in."""
REWARD_TABLE = RewardTable(
    (
        RewardTerm("pegs_inserted", SOCKET_COUNT * INSERTION_VALUE),
        *PEG_TERMS,
        RewardTerm("panel_reach", 4.0, sigma=0.25),
        RewardTerm("panel_grasp", 8.0),
        RewardTerm("panel_lift", 16.0, sigma=0.05),
        RewardTerm("panel_place", 512.0, sigma=0.05),
        RewardTerm("panel_orient", 64.0, sigma=0.1),
        *PENALTY_TERMS,
    )
)


MAX_SET_DRAWS = 50


def reachable_solar_set(seed: int, clearance: float, mount: Asset, urdf_path: str) -> tuple:
    """The procedural layout and pegs of ``seed``, drawn again (deterministically) while some peg has no resting
    face that passes the solvability checks (``solar_face_checks``) for the arm described by ``urdf_path`` on
    ``mount``. The layout's ``feasibility`` dict (on the first peg's ``info``, ``feasibility_record``) records how
    many draws it took and each socket's count of faces passing each check; each peg's ``info["insertable_faces"]``
    lists the faces it may lie on."""
    for draw in range(MAX_SET_DRAWS):
        draw_seed = redrawn_seed(seed, draw)
        layout = make_solar_layout(draw_seed, clearance)
        pegs = make_solar_pegs(layout, draw_seed)
        checks = solar_face_checks(layout, pegs, mount, urdf_path)
        if all(bool(c["insertable"].any()) for c in checks):
            pegs[0].info["feasibility"] = feasibility_record(draw + 1, checks)
            for peg, c in zip(pegs, checks):
                peg.info["insertable_faces"] = c["insertable"].tolist()
            return layout, pegs
    raise RuntimeError(f"no procedural solar set the arm can assemble in {MAX_SET_DRAWS} draws from seed {seed}")


def solar_face_checks(layout, pegs: list[Asset], mount: Asset, urdf_path: str) -> list[dict[str, torch.Tensor]]:
    """Each peg's checks per resting face at its socket (``envs.arm_reach.face_checks_with_the_arm``: ``reachable``,
    ``grippable``, ``arm_inserts``, and ``insertable``: all of them)."""
    origin = np.eye(4)
    origin[:2, 3] = PANEL_TARGET_XY
    frames = socket_frames(layout)
    return [face_checks_with_the_arm(peg, origin @ frames[f"bottom_{i}"], layout.depth, PEG_REST_XY[i], mount, urdf_path) for i, peg in enumerate(pegs)]


@register_env("SolarPanelAssembly-v1", max_episode_steps=1000)
class SolarPanelAssemblyEnv(SocketClearance, SpaceManipulationEnv):
    """
    **Task Description:**
    Insert four pegs lying in front of the arm into four sockets (two long pegs in the nearer sockets, two short
    ones in the farther), then take the solar panel from behind the arm and lower it onto the four pegs: its
    receptacles slide over the pegs' tops and its plate rests on them. On the Moon, Mars and Earth the arm
    rides the rover (the panel lies on its deck) and the sockets stand on the ground; in orbit everything sits on
    a station's work platform and nothing falls. 50 s episodes: 1000 control steps at 20 Hz.

    **Randomizations:**
    - the assets (during reconfiguration, one consistent set per parallel env): `asset_source="dataset"` gives
      the reference's 20 x 20 mm profile pegs (0.1 and 0.2 m), 22 x 22 mm sockets 20 mm deep on 50 x 50 mm
      posts and the reference panel; `asset_source="procedural"` draws one profile (a 3-8 sided polygon,
      radius 10-16 mm, squashed by 0.6-1) for all four pegs, short pegs 0.09-0.12 m (long ones 0.1 m
      longer), sockets 20-30 mm deep with `clearance` (default 1 mm, at most 1.96 mm), and the panel's size (0.9-1.1x per side,
      the sockets and receptacles moving with it)
    - each peg lies on a random stable side within 1 cm of its place, its tip toward the arm within +-11 deg
      (for procedural sets, only on a side that passes the solvability checks, `solar_face_checks`: the arm can
      hold it over its socket, the fingers can hold it there (at least 1 cm tall, not widest only at its base),
      and the arm, planned with the agent's own model and the mount as an obstacle, takes it where it lies and
      pushes it to its socket's bottom with a grasp tilted at most 45 degrees (`envs.arm_reach`); a set with a peg
      that has none is drawn again, and the first peg's `info["feasibility"]` records the checks);
      the panel within 1 cm / 2 cm / 5 deg of its place on the deck
    - the terrain (or nothing, in orbit) and the sun direction (during reconfiguration); the arm's initial joints

    **Success Conditions:**
    - every socket holds a peg of its length inserted as in Peg-in-Hole (at least 90% of the depth, axes within
      5 deg)
    - the panel's seat (its plate's underside centre) is within 1 cm and 5 deg of its target, on the pegs'
      tops (either way round: the panel is symmetric under a half turn)
    - the panel is released

    **Latches:** each socket holds a peg inserted in it (as Peg-in-Hole's hole does) and the pegs' tops hold a
    seated panel: the part is pulled into its seat as hard as 1 g would, its motion damped
    (`envs.insertion.latch_force`), so that in orbit released parts stay where they were put. Nothing that is
    not inserted (or seated) is captured.

    **State observation:** every peg's pose and its target socket (the one it is inserted in; else its own, unless
    another peg fills it; else the other of its length) seen from the peg's end, as Peg-in-Hole observes its hole;
    and the same for the next peg (`next_*`: the one in the hand, else the first in `FILL_ORDER` not yet
    inserted), so that a policy finds the peg it is placing in one place.

    **Reward:** staged, so that progress is monotone: 169 per filled socket (`pegs_inserted`), plus
    Peg-in-Hole's dense terms (reach 1, grasp 4, lift 8, axis 8, twist 4, entrance 16, bottom 128, each below
    its stage's 169) for the unplaced peg furthest along; once all four are in, the panel's terms (reference
    weights: reach 4/0.25, grasp 8, lift 16/0.05, place 512/0.05, and orientation 64/0.1 rad). A grasp or
    lift counts as done once the panel is seated, so releasing it loses nothing. `info["stage"]` counts
    completed stages: 0-4 sockets filled, then panel grasped, lifted, seated, released (8 = success).
    Success gives the table's maximum (1449: every term's weight, the peg terms' 169 included);
    `normalized_dense` maps [-1.5, 1449] onto [0, 1].
    """

    SUPPORTED_DOMAINS = ("moon", "mars", "orbit", "earth")
    DEFAULT_DOMAIN = "moon"
    EPISODE_SECONDS = 50.0
    REWARD_TABLE = REWARD_TABLE

    CLEARANCE_CHECK = staticmethod(check_socket_clearance)

    def _make_mount(self):
        return make_rover(cargo_bin=False) if self.domain.has_ground else make_station()

    @property
    def deck_height(self) -> float:
        """Height of the surface the panel starts on."""
        return DECK_HEIGHT if self.domain.has_ground else 0.0

    def _load_scene(self, options: dict):
        self._load_domain_scene()
        seeds = self._asset_seeds()
        if self.asset_source == "procedural":
            sets = [reachable_solar_set(seed, self.clearance, self.mount, self.agent.urdf_path) for seed in seeds]
            layouts, pegs = [layout for layout, _ in sets], [set_pegs for _, set_pegs in sets]
        else:
            long, short = load_dataset_object("profile_peg_long"), load_dataset_object("profile_peg_short")
            layouts = [_DATASET_LAYOUT] * self.num_envs
            pegs = [[long if i in LONG_SOCKETS else short for i in range(SOCKET_COUNT)]] * self.num_envs
        bases = [make_socket_base(layout) for layout in layouts]
        panels = [make_panel(layout) for layout in layouts]
        target = sapien.Pose(p=[*PANEL_TARGET_XY, 0.0])
        self.socket_base = build_actor_per_env(self.scene, bases, "socket_base", body_type="static", initial_pose=target)
        self.socket_assets = bases
        self.peg_assets = pegs
        # awake however slowly they drift: a part let go in orbit must drift off unless a latch holds it
        self.pegs = [self.build_graspable([p[i] for p in pegs], f"peg_{i}", never_sleep=True) for i in range(SOCKET_COUNT)]
        self.panel = self.build_graspable(panels, "panel", never_sleep=True)
        self.panel_assets = panels
        self._store_task_geometry(pegs, bases, panels)

    def _store_task_geometry(self, pegs, bases, panels):
        device = self.device
        as_tensor = lambda x: torch.as_tensor(np.asarray(x), dtype=torch.float32, device=device)  # noqa: E731
        origin = np.eye(4)
        origin[:2, 3] = PANEL_TARGET_XY
        sockets = range(SOCKET_COUNT)
        self.insertion = PegInsertion.from_assets(
            pegs=pegs,
            hole_entrances=[[origin @ b.frames[f"entrance_{i}"] for i in sockets] for b in bases],
            hole_bottoms=[[origin @ b.frames[f"bottom_{i}"] for i in sockets] for b in bases],
            hole_depths=[[b.info["depth"]] * SOCKET_COUNT for b in bases],
            symmetry_orders=[[b.info["symmetry_order"]] * SOCKET_COUNT for b in bases],
            device=device,
        )
        self._seat_in_panel = as_tensor([p.frames["seat"] for p in panels])
        self._handle_in_panel = as_tensor([p.frames["handle"] for p in panels])
        target = np.eye(4)
        target[:3, 3] = (*PANEL_TARGET_XY, SEAT_HEIGHT)
        self.panel_target = as_tensor([target] * self.num_envs)
        self._peg_placements = [peg_placement([p[i] for p in pegs], device) for i in sockets]
        if self.asset_source == "procedural":
            for i, placement in enumerate(self._peg_placements):
                allow_insertable_faces(placement, [p[i] for p in pegs])
        self._socket_class = torch.as_tensor([i in LONG_SOCKETS for i in range(SOCKET_COUNT)], device=device)
        # the sockets each peg may fill: those of its length
        self._fits = self._socket_class[:, None] == self._socket_class[None, :]

    def _after_reconfigure(self, options: dict):
        super()._after_reconfigure(options)
        self._peg_start_height = torch.zeros((self.num_envs, SOCKET_COUNT), device=self.device)
        self._panel_start_height = torch.zeros(self.num_envs, device=self.device)
        self._peg_masses = [peg.mass.to(self.device) for peg in self.pegs]
        self._panel_mass = self.panel.mass.to(self.device)

    def _latch_forces(self):
        """Each socket latches a peg inserted in it, and the pegs' tops latch a seated panel (see the card)."""
        in_socket = seated_pairs(self.insertion, self.insertion.all_pair_measures(self.peg_end_frames()), self._fits)
        forces = pegs_latched_in_holes(self.pegs, self._peg_masses, in_socket, self.insertion.hole_bottom)
        _, _, seated = self._seat_error()
        forces.append((self.panel, latch_force(seated, -self.panel_target[:, :3, 2], self.panel.linear_velocity, self._panel_mass)))
        return forces

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        with torch.device(self.device):
            b = len(env_idx)
            rng = self._batched_episode_rng[env_idx]
            self._initialize_agent(env_idx)
            for i, (peg, placement) in enumerate(zip(self.pegs, self._peg_placements)):
                quat = lying_peg_orientation(placement, env_idx, rng)
                position = torch.zeros((b, 3))
                position[:, :2] = torch.tensor(PEG_REST_XY[i]) + torch.as_tensor(rng.uniform(-PEG_JITTER, PEG_JITTER, size=(2,)), dtype=torch.float32)
                position[:, 2] = placement.height_on_ground(env_idx, quat, PEG_DROP_CLEARANCE)
                peg.set_pose(Pose.create_from_pq(position, quat))
                self._peg_start_height[env_idx, i] = position[:, 2]
            jitter = torch.as_tensor(rng.uniform(-1.0, 1.0, size=(3,)), dtype=torch.float32) * torch.tensor(PANEL_START_JITTER)
            yaw = jitter[:, 2]
            seat = torch.zeros((b, 3))
            seat[:, :2] = torch.tensor(PANEL_START_XY) + jitter[:, :2]
            seat[:, 2] = self.deck_height + RECEPTACLE_DEPTH + PANEL_DROP_CLEARANCE
            quat = torch.stack([torch.cos(yaw / 2), torch.zeros(b), torch.zeros(b), torch.sin(yaw / 2)], dim=-1)
            # the panel's origin is its centre of mass: place it so that its seat lands at `seat`
            seat_offset = self._seat_in_panel[env_idx, :3, 3]
            position = seat - (quaternion_to_matrix(quat) @ seat_offset.unsqueeze(-1)).squeeze(-1)
            self.panel.set_pose(Pose.create_from_pq(position, quat))
            self._panel_start_height[env_idx] = seat[:, 2]

    # ------------------------------------------------------------------ measures
    def peg_end_frames(self) -> torch.Tensor:
        """World poses (n, 4 pegs, 2 ends, 4, 4) of the pegs' insertable ends (the second repeats the first if only one)."""
        positions = torch.stack([peg.pose.p for peg in self.pegs], dim=1)
        quaternions = torch.stack([peg.pose.q for peg in self.pegs], dim=1)
        return self.insertion.end_frames(positions, quaternions)

    def panel_seat(self) -> torch.Tensor:
        pose = self.panel.pose
        return pose_matrix(pose.p, pose.q) @ self._seat_in_panel

    def _seat_error(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The panel seat's distance and angle from its target, and whether it is seated (within tolerance)."""
        distance, angle = pose_error(self.panel_seat(), self.panel_target, half_turn_symmetric=True)
        return distance, angle, (distance <= SEAT_DISTANCE_TOLERANCE) & (angle <= SEAT_ANGLE_TOLERANCE)

    def panel_handle(self) -> torch.Tensor:
        pose = self.panel.pose
        return pose_matrix(pose.p, pose.q) @ self._handle_in_panel

    def evaluate(self):
        measures = self.insertion.all_pair_measures(self.peg_end_frames())
        in_socket = seated_pairs(self.insertion, measures, self._fits)
        socket_filled = in_socket.any(dim=1)
        sockets_filled = socket_filled.sum(dim=1)
        all_filled = sockets_filled == SOCKET_COUNT
        seat_distance, seat_angle, panel_seated = self._seat_error()
        panel_grasped = self.is_grasping(self.panel)
        pegs_grasped = torch.stack([self.is_grasping(peg) for peg in self.pegs], dim=1)
        panel_lift = self.panel_seat()[:, 2, 3] - self._panel_start_height
        panel_lifted = panel_lift >= PANEL_LIFT_BAND[0]
        success = all_filled & panel_seated & ~panel_grasped
        panel_stages = (panel_grasped | panel_seated).int() + (panel_lifted | panel_seated).int() + panel_seated.int() + success.int()
        return dict(
            success=success,
            stage=sockets_filled + torch.where(all_filled, panel_stages, torch.zeros_like(panel_stages)),
            socket_filled=socket_filled,
            peg_inserted=in_socket.any(dim=2),
            peg_in_socket=in_socket,
            sockets_filled=sockets_filled,
            panel_seated=panel_seated,
            panel_grasped=panel_grasped,
            pegs_grasped=pegs_grasped,
            panel_lift=panel_lift,
            seat_distance=seat_distance,
            seat_angle=seat_angle,
            **{f"pair_{k}": v for k, v in measures.items()},
        )

    def target_sockets(self, info: dict) -> torch.Tensor:
        """(n, 4) the socket each peg should go to: the one it is inserted in, if any; else its own if no other peg
        fills it; else the other of its length."""
        in_socket = info["peg_in_socket"]  # (n, pegs, sockets)
        own = torch.arange(SOCKET_COUNT, device=self.device).expand(len(in_socket), SOCKET_COUNT)
        partner = torch.tensor([1, 0, 3, 2], device=self.device).expand(len(in_socket), SOCKET_COUNT)
        own_filled_by_another = info["socket_filled"] & ~in_socket.diagonal(dim1=1, dim2=2)
        target = torch.where(own_filled_by_another, partner, own)
        return torch.where(in_socket.any(dim=2), in_socket.int().argmax(dim=2), target)

    # ------------------------------------------------------------------ observations
    def _get_obs_extra(self, info: dict):
        tcp_position, tcp_rotation = self.tcp_frame()
        obs = self._shared_obs_extra(tcp_position, tcp_rotation)
        obs["panel_grasped"] = info["panel_grasped"].float().unsqueeze(-1)
        obs["socket_filled"] = info["socket_filled"].float()
        if self.obs_mode_struct.use_state:
            n = self.num_envs
            pegs = torch.stack([peg.pose.raw_pose for peg in self.pegs], dim=1)
            peg_position, peg_rotation = relative_pose(
                tcp_position[:, None], tcp_rotation[:, None], pegs[..., :3], rotation_matrix(pegs[..., 3:])
            )
            entrance = self.insertion.hole_entrance
            entrance_position, _ = relative_pose(tcp_position[:, None], tcp_rotation[:, None], entrance[..., :3, 3], entrance[..., :3, :3])
            handle = self.panel_handle()
            handle_position, handle_rotation = relative_pose(tcp_position, tcp_rotation, handle[:, :3, 3], handle[:, :3, :3])
            socket_entrance, socket_bottom, socket_rotation = self._target_sockets_in_peg_ends(info)
            rows, grasped = torch.arange(n, device=self.device), info["pegs_grasped"]
            next_peg = self._next_peg(grasped, info["peg_inserted"])
            seat = self.panel_seat()
            target_position, target_rotation = relative_pose(seat[:, :3, 3], seat[:, :3, :3], self.panel_target[:, :3, 3], self.panel_target[:, :3, :3])
            obs.update(
                pegs_pos_in_tcp=peg_position.reshape(n, -1),
                pegs_rot6d_in_tcp=rotation_6d(peg_rotation).reshape(n, -1),
                sockets_pos_in_tcp=entrance_position.reshape(n, -1),
                target_entrances_in_peg_ends=socket_entrance.reshape(n, -1),
                target_bottoms_in_peg_ends=socket_bottom.reshape(n, -1),
                target_sockets_rot6d_in_peg_ends=rotation_6d(socket_rotation).reshape(n, -1),
                next_peg=torch.nn.functional.one_hot(next_peg, SOCKET_COUNT).float(),
                next_peg_grasped=grasped[rows, next_peg].float().unsqueeze(-1),
                next_peg_pos_in_tcp=peg_position[rows, next_peg],
                next_peg_rot6d_in_tcp=rotation_6d(peg_rotation[rows, next_peg]),
                next_entrance_in_peg_end=socket_entrance[rows, next_peg],
                next_bottom_in_peg_end=socket_bottom[rows, next_peg],
                next_socket_rot6d_in_peg_end=rotation_6d(socket_rotation[rows, next_peg]),
                peg_inserted=info["peg_inserted"].float(),
                socket_depth=self.insertion.hole_depth[:, :1],
                symmetry_order=self.insertion.symmetry_order[:, :1].float(),
                handle_pos_in_tcp=handle_position,
                handle_rot6d_in_tcp=rotation_6d(handle_rotation),
                target_pos_in_seat=target_position,
                target_rot6d_in_seat=rotation_6d(target_rotation),
            )
        return obs

    def _next_peg(self, grasped: torch.Tensor, inserted: torch.Tensor) -> torch.Tensor:
        """(n,) the peg being placed: the one in the hand, else the first in ``FILL_ORDER`` not yet inserted (the last
        in it once all are), from ``grasped`` and ``inserted`` (n, 4)."""
        rank = torch.empty(SOCKET_COUNT, dtype=torch.long, device=self.device)
        rank[list(FILL_ORDER)] = torch.arange(SOCKET_COUNT, device=self.device)
        waiting = (~inserted) * (SOCKET_COUNT - rank)  # 4 for the first in the order .. 1 for the last, 0 if in
        last = rank == SOCKET_COUNT - 1
        score = (4 * SOCKET_COUNT) * grasped.long() + 2 * waiting + last.long()
        return score.argmax(dim=1)

    def _target_sockets_in_peg_ends(self, info: dict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """For each peg, its target socket (``target_sockets``) seen from the peg's end nearest that socket's
        entrance, as Peg-in-Hole observes its hole: the entrance's and the bottom's positions (n, 4, 3) and the
        socket's rotation (n, 4, 3, 3) in that end's frame."""
        rows = torch.arange(self.num_envs, device=self.device)[:, None]
        pegs = torch.arange(SOCKET_COUNT, device=self.device)[None]
        target = self.target_sockets(info)
        end = self.peg_end_frames()[rows, pegs, info["pair_peg_end"][rows, pegs, target]]
        return hole_in_peg_end(end, self.insertion.hole_entrance[rows, target], self.insertion.hole_bottom[rows, target])

    # ------------------------------------------------------------------ reward
    def _reward_inputs(self, info: dict) -> dict[str, torch.Tensor]:
        all_filled = info["sockets_filled"] == SOCKET_COUNT
        peg = self._peg_inputs(info, all_filled)
        tcp = self.agent.tcp.pose.p
        panel_seated = info["panel_seated"]
        far = torch.full_like(info["seat_distance"], float("inf"))
        gate = lambda value: torch.where(all_filled, value, far)  # noqa: E731
        return dict(
            pegs_inserted=info["sockets_filled"].float() / SOCKET_COUNT,
            **peg,
            panel_reach=gate(torch.linalg.norm(tcp - self.panel_handle()[:, :3, 3], dim=-1)),
            panel_grasp=(all_filled & (info["panel_grasped"] | panel_seated)).float(),
            panel_lift=gate(torch.where(panel_seated, torch.zeros_like(far), band_distance(info["panel_lift"], *PANEL_LIFT_BAND))),
            panel_place=gate(info["seat_distance"]),
            panel_orient=gate(info["seat_angle"]),
        )

    def _peg_inputs(self, info: dict, all_filled: torch.Tensor) -> dict[str, torch.Tensor]:
        """Peg-in-Hole's term inputs for the not-yet-inserted peg whose terms add up to the most."""
        n = self.num_envs
        rows = torch.arange(n, device=self.device)[:, None]
        target = self.target_sockets(info)
        pair = lambda key: info[f"pair_{key}"][rows, torch.arange(SOCKET_COUNT, device=self.device)[None], target]  # noqa: E731
        positions = torch.stack([peg.pose.p for peg in self.pegs], dim=1)
        grasped = info["pegs_grasped"]
        measures = {key: pair(key) for key in ("axis_angle", "twist_error", "tip_to_entrance", "tip_to_bottom")}
        inputs = insertion_inputs(self.agent.tcp.pose.p[:, None], positions, grasped.float(), self._peg_start_height, measures)
        inputs = {f"peg_{name}": value for name, value in inputs.items()}
        progress = sum(term(inputs[term.name]) for term in PEG_TERMS)
        progress = progress.masked_fill(info["peg_inserted"], -1.0)
        best = progress.argmax(dim=1)
        chosen = {name: value[rows[:, 0], best] for name, value in inputs.items()}
        # once all four are in, the peg terms rest at zero
        off = {"peg_grasp": torch.zeros(n, device=self.device)}
        return {name: torch.where(all_filled, off.get(name, torch.full_like(value, float("inf"))), value) for name, value in chosen.items()}


_DATASET_LAYOUT = dataset_layout(short_length=0.1, width=0.02, clearance=0.001, depth=0.02)
"""The reference: 100 and 200 mm profile pegs 20 mm square, sockets 22 mm square and 20 mm deep."""
