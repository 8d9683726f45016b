import numpy as np
import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.pose import Pose

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.debris_paths import CANDIDATE_STARTS, SHOULDER_HEIGHT, first_catchable, seconds_within_reach
from mani_skill_space.envs.base import PENALTY_TERMS, SpaceManipulationEnv
from mani_skill_space.geometry import relative_pose, rotation_6d, rotation_matrix, step_velocities
from mani_skill_space.kwarg_checks import checked_number
from mani_skill_space.procgen.asset import look_at
from mani_skill_space.procgen.debris import make_debris
from mani_skill_space.procgen.mounts import make_rover, make_station
from mani_skill_space.rewards import RewardTable, RewardTerm

DEBRIS_START = (1.0, 0.0, 0.5)
"""Mean start position (world; the arm's base is at (0, 0, 0.25)), as in the reference."""
DEBRIS_START_SPREAD = 0.25
DRIFT_SPEED = (0.15, 0.25)
"""Speed toward the arm (m/s) at difficulty 1, plus up to LATERAL_SPEED sideways and vertically."""
LATERAL_SPEED = 0.05
TUMBLE_RATE = np.pi
"""Angular velocity per axis, up to this (rad/s) at difficulty 1."""
SLOWEST_SPEED_SCALE = 0.4
"""At difficulty 0 the debris drifts at 40% of the reference speeds and does not tumble."""
MAX_DIFFICULTY = 2.0
"""The hardest setting: twice the reference's tumble (up to 2 pi rad/s per axis, 18 deg per 50 ms control step) and
1.6x its drift (up to 0.4 m/s: the 1 m to the arm in 2.5 s, a quarter of the episode). A curriculum knob around the
reference's setting (1), not a way to make capture impossible: beyond 2 the debris turns more than a twentieth of a
turn between two actions and reaches the arm within the first seconds."""
LOB_TARGET_X = 0.55
CALM_SPEED = 0.05
CALM_SPIN = 0.1
CALM_SECONDS = 0.5
OUT_OF_REACH = 1.5
"""Distance (m) from the arm's base beyond which debris moving away counts as lost."""
DATASET_DEBRIS = ("cubesat_1u", "cubesat_3u", "profile_peg_long")
NO_GRASP_DISTANCE = 1e3
"""Stands in for the debris' speed in the damping terms while it is not grasped (they then give nothing)."""

REWARD_TABLE = RewardTable(
    (
        RewardTerm("reach", 1.0, sigma=0.25),
        RewardTerm("approach", 2.0, sigma=0.05),
        RewardTerm("grasp", 4.0),
        RewardTerm("slow_down", 4.0, sigma=0.1),
        RewardTerm("stop_spin", 4.0, sigma=0.5),
        *PENALTY_TERMS,
    )
)


@register_env("DebrisCapture-v1", max_episode_steps=200)
class DebrisCaptureEnv(SpaceManipulationEnv):
    """
    **Task Description:**
    A piece of space debris drifts toward an arm on a station's truss, tumbling; grasp it and bring it to rest
    in the hand. In orbit there is no gravity (and no damping: untouched debris keeps its momentum); on an
    asteroid the arm rides the rover and the debris falls slowly along a ballistic arc. 10 s episodes: 200
    control steps at 20 Hz, physics at 100 Hz.

    **Randomizations:**
    - the debris (during reconfiguration, one per parallel env): `asset_source="procedural"` gives a small
      satellite (a 3.5-4.5 cm bus with solar wings and antennas, half the pieces), a flat structural fragment or a
      rock; `asset_source="dataset"` gives a 1U or 3U CubeSat (at 40% scale, to fit the gripper whichever way it turns) or the 200 mm
      profile peg. Mass and inertia follow from the shape (CubeSat density 1330 kg/m^3, aluminium 2700, rock 2000)
    - the start: (1.0, 0, 0.5) m +- 0.25 m per axis, a uniformly random orientation; the drift toward the arm
      0.15-0.25 m/s with up to +-0.05 m/s sideways and vertically, and a tumble of up to +-pi rad/s per axis,
      all at `difficulty=1` (the reference's ranges); `difficulty` d scales the speeds by 0.4 + 0.6 d and the
      tumble by d, d in [0, 2] (0: slow, no tumble; above 1: harder). On the asteroid the debris is also tossed upward just
      enough to come back to its starting height where the arm reaches (a low arc, peaking halfway)

    **Success Conditions:**
    - the debris is grasped and has moved slower than 0.05 m/s and turned slower than 0.1 rad/s for 0.5 s (its
      velocities measured from its poses over the last two control steps)

    **Fail Conditions:**
    - the debris is more than 1.5 m from the arm's base and moving away (it will not come back)

    **Reward:** positive terms only (see `REWARD_TABLE`; each reported in `info["reward_terms"]`): reach
    1 * (1 - tanh(d / 0.25)) and approach 2 * (1 - tanh(d / 0.05)) for the TCP-to-debris distance d, grasp 4,
    and, only while grasped, slow_down 4 * (1 - tanh(|v| / 0.1)) and stop_spin 4 * (1 - tanh(|w| / 0.5)); the
    common small penalties; success gives the maximum (15). The reference penalised the debris' speeds at
    every step (-2|v| - |w|/2pi), which dominated its reward while the debris tumbled freely, so its users could
    not learn from it; here damping earns bounded rewards once the debris is held, and every term stays within
    a few units of the others, so reaching, grasping and damping each move the return.
    """

    SUPPORTED_DOMAINS = ("orbit", "asteroid")
    DEFAULT_DOMAIN = "orbit"
    EPISODE_SECONDS = 10.0
    REWARD_TABLE = REWARD_TABLE
    SUPPORTS_FREE_FLYER = True
    SUPPORTS_OBJECT_SCALE = True

    def __init__(self, *args, difficulty: float = 1.0, **kwargs):
        self.difficulty = self.check_task_kwargs(difficulty=difficulty)["difficulty"]
        super().__init__(*args, **kwargs)

    @classmethod
    def check_task_kwargs(cls, **kwargs) -> dict:
        """The base class's checks, and ``difficulty``: a number in [0, 2] (``MAX_DIFFICULTY``)."""
        checked = super().check_task_kwargs(**kwargs)
        checked["difficulty"] = checked_number(
            "difficulty", kwargs.get("difficulty", 1.0), 0.0, MAX_DIFFICULTY, meaning="0: slow, no tumble; 1: the reference's ranges; 2: twice its tumble"
        )
        return checked

    def _render_camera_pose(self) -> np.ndarray:
        """From the side, seeing the arm and the debris' whole approach."""
        return look_at((0.55, -1.5, 0.95), (0.5, 0.0, 0.4))

    def _make_mount(self):
        return make_rover() if self.domain.has_ground else make_station()

    def _load_scene(self, options: dict):
        self._load_domain_scene()
        seeds = self._asset_seeds()
        if self.asset_source == "procedural":
            assets = [make_debris(seed) for seed in seeds]
        else:
            assets = [load_dataset_object(DATASET_DEBRIS[seed % len(DATASET_DEBRIS)]) for seed in seeds]
        assets = [self.factors.scaled(asset) for asset in assets]
        self.debris_assets = assets
        self.debris = self.build_graspable(assets, "debris", never_sleep=True)
        # free flight: no damping
        self.debris.linear_damping = 0.0
        self.debris.angular_damping = 0.0
        self._calm_steps = torch.zeros(self.num_envs, dtype=torch.int32, device=self.device)
        self._grasped = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        self._last_debris_pose = torch.zeros((self.num_envs, 7), device=self.device)
        self._debris_velocity = torch.zeros((self.num_envs, 3), device=self.device)
        self._debris_spin_velocity = torch.zeros((self.num_envs, 3), device=self.device)
        self._step_velocity = torch.zeros((self.num_envs, 3), device=self.device)
        self._step_spin_velocity = torch.zeros((self.num_envs, 3), device=self.device)
        self.start_checks = dict(
            draws=torch.zeros(self.num_envs, dtype=torch.int32, device=self.device),
            seconds_within_reach=torch.zeros(self.num_envs, device=self.device),
        )
        """Each env's episode start passed the solvability check (``debris_paths``): how many candidate starts were
        drawn to find it, and how long its path stays within the arm's reach once the hand can be there."""

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        with torch.device(self.device):
            b = len(env_idx)
            rng = self._batched_episode_rng[env_idx]
            self._initialize_agent(env_idx)
            position, quaternion, velocity, spin = self._candidate_starts(rng, b)
            seconds = seconds_within_reach(position, velocity, self._gravity(), self._shoulder(env_idx)[:, None], camera_post=not self.free_flyer)
            pick = first_catchable(seconds)
            choose = lambda x: x[torch.arange(b), pick]  # noqa: E731
            position, quaternion, velocity, spin = choose(position), choose(quaternion), choose(velocity), choose(spin)
            pose = Pose.create_from_pq(position, quaternion)
            self.debris.set_pose(pose)
            self.debris.set_linear_velocity(velocity)
            self.debris.set_angular_velocity(spin)
            self.start_checks["draws"][env_idx] = (pick + 1).int()
            self.start_checks["seconds_within_reach"][env_idx] = choose(seconds)
            self._calm_steps[env_idx] = 0
            self._grasped[env_idx] = False
            self._last_debris_pose[env_idx] = pose.raw_pose
            self._debris_velocity[env_idx] = velocity
            self._debris_spin_velocity[env_idx] = spin
            self._step_velocity[env_idx] = velocity
            self._step_spin_velocity[env_idx] = spin

    def _candidate_starts(self, rng, b: int) -> tuple[torch.Tensor, ...]:
        """``CANDIDATE_STARTS`` starts per env (b, K, ...): position, wxyz orientation, drift (with the lob under
        gravity) and tumble, each from the reference's ranges scaled by ``difficulty``."""
        k = CANDIDATE_STARTS
        as_tensor = lambda x: torch.as_tensor(x, dtype=torch.float32).reshape(b, k, -1).squeeze(-1)  # noqa: E731
        position = torch.tensor(DEBRIS_START) + as_tensor(rng.uniform(-DEBRIS_START_SPREAD, DEBRIS_START_SPREAD, size=(k, 3)))
        quaternion = as_tensor(rng.normal(size=(k, 4)))
        quaternion = quaternion / torch.linalg.norm(quaternion, dim=-1, keepdim=True)
        scale = SLOWEST_SPEED_SCALE + (1 - SLOWEST_SPEED_SCALE) * self.difficulty
        drift = [-as_tensor(rng.uniform(*DRIFT_SPEED, size=(k,))), as_tensor(rng.uniform(-LATERAL_SPEED, LATERAL_SPEED, size=(k,))), as_tensor(rng.uniform(-LATERAL_SPEED, LATERAL_SPEED, size=(k,)))]
        velocity = torch.stack(drift, dim=-1) * scale
        velocity = velocity + self._lob(position, velocity)
        spin = as_tensor(rng.uniform(-TUMBLE_RATE, TUMBLE_RATE, size=(k, 3))) * self.difficulty
        return position, quaternion, velocity, spin

    def _gravity(self) -> torch.Tensor:
        return torch.as_tensor(np.asarray(self.sim_config.scene_config.gravity), dtype=torch.float32, device=self.device)

    def _shoulder(self, env_idx: torch.Tensor) -> torch.Tensor:
        """(b, 3) the arm's shoulder joint, ``SHOULDER_HEIGHT`` above its base."""
        return self.agent.robot.pose.p[env_idx] + torch.tensor([0.0, 0.0, SHOULDER_HEIGHT], device=self.device)

    def _lob(self, position: torch.Tensor, velocity: torch.Tensor) -> torch.Tensor:
        """Under gravity (the asteroid), the upward velocity that brings the debris back to its starting height
        when it reaches the arm (x = LOB_TARGET_X), so that it arrives along an arc rather than on the ground."""
        gravity = float(-self.sim_config.scene_config.gravity[2])
        flight_time = (position[..., 0] - LOB_TARGET_X) / -velocity[..., 0]
        lob = torch.zeros_like(velocity)
        lob[..., 2] = gravity * flight_time / 2
        return lob

    def _update_task_state(self):
        """Once per control step: the debris' velocities, measured from how far it moved and turned over the last
        two control steps, and how long it has been held calm. From poses, because PhysX's own velocities of a
        body squeezed between the fingers carry the contact solver's bias (a debris held still can report a spin
        of several rad/s); over two steps, because such a body also rocks back and forth from one step to the
        next (by about 0.15 degrees: 0.1 rad/s from one step's turn, none over two)."""
        pose = self.debris.pose
        last = self._last_debris_pose
        velocity, spin = step_velocities(last[:, :3], last[:, 3:], pose.p, pose.q, 1.0 / self.control_freq)
        self._debris_velocity = (velocity + self._step_velocity) / 2
        self._debris_spin_velocity = (spin + self._step_spin_velocity) / 2
        self._step_velocity, self._step_spin_velocity = velocity, spin
        self._last_debris_pose = pose.raw_pose.clone()
        self._grasped = self.is_grasping(self.debris)  # (a contact query: once per step, evaluate reuses it)
        calm = self._grasped & (self._debris_speed() < CALM_SPEED) & (self._debris_spin() < CALM_SPIN)
        self._calm_steps = torch.where(calm, self._calm_steps + 1, torch.zeros_like(self._calm_steps))

    def get_state_dict(self):
        """The base class's state plus, under ``"task"``, what this task tracks across steps (the debris' last pose
        and measured velocities, how long it has been held calm), so that restoring a state restores its evaluation."""
        state = super().get_state_dict()
        state["task"].update(
            last_debris_pose=self._last_debris_pose.clone(),
            debris_velocity=self._debris_velocity.clone(),
            debris_spin_velocity=self._debris_spin_velocity.clone(),
            step_velocity=self._step_velocity.clone(),
            step_spin_velocity=self._step_spin_velocity.clone(),
            calm_steps=self._calm_steps[:, None].float(),
        )
        return state

    def set_state_dict(self, state: dict, env_idx: torch.Tensor = None):
        super().set_state_dict(state, env_idx)
        task = self._task_state_of(state)
        rows = slice(None) if env_idx is None else env_idx
        if "last_debris_pose" not in task:  # a state without the debris' history: measure from here on
            self._last_debris_pose[rows] = self.debris.pose.raw_pose[rows].clone()
            return
        self._last_debris_pose[rows] = task["last_debris_pose"]
        self._debris_velocity[rows] = task["debris_velocity"]
        self._debris_spin_velocity[rows] = task["debris_spin_velocity"]
        self._step_velocity[rows] = task.get("step_velocity", task["debris_velocity"])
        self._step_spin_velocity[rows] = task.get("step_spin_velocity", task["debris_spin_velocity"])
        self._calm_steps[rows] = task["calm_steps"][:, 0].round().int()

    def _debris_speed(self) -> torch.Tensor:
        return torch.linalg.norm(self._debris_velocity, dim=-1)

    def _debris_spin(self) -> torch.Tensor:
        return torch.linalg.norm(self._debris_spin_velocity, dim=-1)

    def evaluate(self):
        offset = self.debris.pose.p - self.agent.robot.pose.p
        moving_away = (offset * self._debris_velocity).sum(dim=-1) > 0
        calm_time = self._calm_steps.float() / self.control_freq
        return dict(
            success=calm_time >= CALM_SECONDS,
            fail=(torch.linalg.norm(offset, dim=-1) > OUT_OF_REACH) & moving_away,
            is_grasped=self._grasped,
            debris_speed=self._debris_speed(),
            debris_spin=self._debris_spin(),
            calm_time=calm_time,
        )

    def _get_obs_extra(self, info: dict):
        tcp_position, tcp_rotation = self.tcp_frame()
        obs = self._shared_obs_extra(tcp_position, tcp_rotation)
        obs["is_grasped"] = info["is_grasped"].float().unsqueeze(-1)
        if self.obs_mode_struct.use_state:
            debris = self.debris.pose
            position, rotation = relative_pose(tcp_position, tcp_rotation, debris.p, rotation_matrix(debris.q))
            obs.update(
                debris_pos_in_tcp=position,
                debris_rot6d_in_tcp=rotation_6d(rotation),
                debris_linear_velocity=self._debris_velocity,
                debris_angular_velocity=self._debris_spin_velocity,
                calm_time=info["calm_time"].unsqueeze(-1),
            )
        return obs

    def _reward_inputs(self, info: dict) -> dict[str, torch.Tensor]:
        distance = torch.linalg.norm(self.agent.tcp.pose.p - self.debris.pose.p, dim=-1)
        grasped = info["is_grasped"]
        far = torch.full_like(distance, NO_GRASP_DISTANCE)
        return dict(
            reach=distance,
            approach=distance,
            grasp=grasped,
            slow_down=torch.where(grasped, info["debris_speed"], far),
            stop_spin=torch.where(grasped, info["debris_spin"], far),
        )
