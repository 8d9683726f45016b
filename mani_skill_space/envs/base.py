"""The base class of every mani-skill-space task: domains, robot mounting, cameras, observations, rewards.

Tasks subclass ``SpaceManipulationEnv`` like ManiSkill tasks subclass ``BaseEnv``, and add:
- ``SUPPORTED_DOMAINS``, ``SUPPORTED_ASSET_SOURCES``, ``EPISODE_SECONDS``, ``REWARD_TABLE`` class constants;
- ``_make_mount()``: the static structure carrying the arm (an ``Asset`` with ``arm_mount`` and
  ``base_camera`` frames);
- ``_reward_inputs(info)``: one value per ``REWARD_TABLE`` term except the shared penalties.
The base class reports every reward term in ``info["reward_terms"]`` in all reward modes.

Rotation actions of ``pd_ee_delta_pose``: we keep ManiSkill 3.0.1's controller unchanged so that policies,
demonstrations and tools behave exactly as on ManiSkill's own tasks. In 3.0.1 a positive rotation action turns
the TCP the negative way about that axis (ManiSkill issue #1469); ``tests/envs/test_controller_convention.py``
pins this so an upgrade that fixes it is noticed.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, Callable, ClassVar, Optional, Union

import numpy as np
import sapien
import torch
from mani_skill.agents.registration import REGISTERED_AGENTS
from mani_skill.agents.robots import Panda, PandaWristCam
from mani_skill.envs.sapien_env import BaseEnv
from mani_skill.envs.utils.observations import ALL_VISUAL_TEXTURES, parse_obs_mode_to_struct
from mani_skill.sensors.camera import CameraConfig
from mani_skill.envs.utils.randomization.batched_rng import BatchedRNG
from mani_skill.utils.geometry.rotation_conversions import quaternion_multiply, quaternion_to_matrix
from mani_skill.utils.gym_utils import inv_scale_action
from mani_skill.utils.structs.pose import Pose
from mani_skill.utils.structs.types import DefaultMaterialsConfig, GPUMemoryConfig, SceneConfig, SimConfig

from mani_skill_space.dataset import sky_texture_path
from mani_skill_space.domains import DOMAINS, get_domain, sample_sun_direction
from mani_skill_space.delay import DelayLine, check_delay_kwargs, drift_moves, with_missing_replaced
from mani_skill_space.envs.building import bounding_radius, build_actor_per_env, build_asset_actor, build_dynamic_per_env, build_flat_ground, build_skydome, padded_points
from mani_skill_space.factors import FactorShifts, camera_offsets, check_factor_kwargs, jittered_camera_frames
from mani_skill_space.geometry import relative_pose, rotation_6d, rotation_matrix
from mani_skill_space.kwarg_checks import KwargError, checked_choice, checked_natural, checked_number
from mani_skill_space.levels import LevelRange, check_level_kwargs
from mani_skill_space.procgen.asset import Asset, look_at
from mani_skill_space.procgen.peg_hole import DEFAULT_CLEARANCE, check_clearance
from mani_skill_space.procgen.resting import resting_orientations
from mani_skill_space.procgen.servicer import BUS_LINK, MOUNTS, check_servicer_mass
from mani_skill_space.procgen.terrain import TERRAIN_HALF_EXTENT, make_flat_ground, make_terrain
from mani_skill_space.rewards import RewardTable, RewardTerm, action_rate

SENSOR_SIZE = 64
"""Camera resolution of the reference (64x64); override with ``sensor_configs=dict(width=..., height=...)``."""
SENSOR_FAR = 25.0
ENV_SPACING = 2 * TERRAIN_HALF_EXTENT + 2.0
"""GPU sub-scenes share one physics world: keep each env's terrain clear of its neighbours'."""
GRASP_MIN_FORCE = 5.0
"""Grasped = both fingers press on the object with more than 5 N (reference definition)."""
FINGER_REACH = 0.15
"""m: no point of the Panda's fingers (open or closed) or finger links is farther than this from the TCP (they
reach about 0.07 m): an object whose collision geometry is farther from the TCP cannot be touched by them."""
GRASPABLE_SOLVER_POSITION_ITERATIONS = 30
"""PhysX position iterations of every object the robot grasps (``build_graspable``); the hand holding one is solved
with as many (PhysX solves an island with the most any of its bodies asks for). At ManiSkill's 15 for the whole scene
the Panda's fingers, driven shut, sink into a light part: on a 24 g procedural peg (Multi-Peg-in-Hole, orbit, seed
62016) each closed 1.6 mm farther than at 30, the peg carried 0.3 m/s and 18 rad/s of velocity that its pose in the
hand did not show, and it sprang out of the fingers when the wrist turned; at 20 it still did, at 30 it stays
(ManiSkill's ``SceneConfig`` notes that stable grasps want 20 or more). A ``sim_config`` asking for more iterations
for the whole scene gives the grasped objects that many."""
ARM_CONTACT_LIMIT = 10.0
"""Contact force (N) on an arm link above which the undesired-contact penalty applies."""
WRIST_CAMERA_EYE = (0.1, 0.0, -0.07)
WRIST_CAMERA_TARGET = (0.0, 0.0, 0.12)
"""Wrist camera in the TCP frame (z = approach direction): beside the hand, looking past the fingertips."""
FULL_COLLECTION_EVERY = 8
"""On physx_cpu a scene rebuild runs Python's full garbage collection once every this many rebuilds, not at every
one: ManiSkill's ``_clear`` forces it to hand GPU memory back at once, and in a process with torch loaded it costs
about three times the rest of the rebuild (a procedural env rebuilds at every episode). The old scenes' cycles
wait at most this many rebuilds (the memory stays flat: ``tests/envs/test_rebuild_memory.py``)."""
DEFAULT_CONTROL_MODE = "pd_ee_delta_pose"
"""The control mode an env gets when none is given (also for ``control_mode=None``, which ManiSkill's tools pass)."""
DEFAULT_QPOS_NOISE = 0.02
MAX_QPOS_NOISE = 1.1
"""Largest ``robot_init_qpos_noise`` (rad): every arm joint starts uniformly within this of the rest pose, and the
Panda's elbow (joint 4) rests 1.108 rad above its lower limit, the least room of any joint; up to 1.1 rad every joint
starts within its limits."""

PENALTY_TERMS = (
    RewardTerm("action_rate", -1.4),
    RewardTerm("arm_contact", -0.1),
)
"""Shared penalties (reference weights): -0.05 * sum over 7 action dims of the squared action change (max 4
each, expressed here as a [0, 1] rate times 1.4), and -0.1 while an arm link is pressed with more than 10 N."""


class SpaceManipulationEnv(BaseEnv):
    SUPPORTED_ROBOTS = ["panda", "panda_wristcam"]
    SUPPORTED_DOMAINS: ClassVar[tuple[str, ...]] = tuple(DOMAINS)
    SUPPORTED_ASSET_SOURCES: ClassVar[tuple[str, ...]] = ("procedural", "dataset")
    DEFAULT_DOMAIN: ClassVar[str] = "moon"
    DEFAULT_ASSET_SOURCE: ClassVar[str] = "procedural"
    EPISODE_SECONDS: ClassVar[float] = 10.0
    SIM_FREQ: ClassVar[int] = 100
    CONTROL_FREQ: ClassVar[int] = 20
    REWARD_TABLE: ClassVar[RewardTable]
    SUPPORTS_OBJECT_SCALE: ClassVar[bool] = False
    """Whether ``object_scale`` applies (tasks whose object fits nothing it must be scaled with, e.g. a socket)."""
    SUPPORTS_FREE_FLYER: ClassVar[bool] = False
    """Whether ``mount="free_flyer"`` applies (in orbit: the arm on a free-floating servicer instead of the station)."""

    agent: Union[Panda, PandaWristCam]

    def __init__(
        self,
        *args,
        domain: Optional[str] = None,
        asset_source: Optional[str] = None,
        robot_uids: str = "panda",
        control_mode: Optional[str] = DEFAULT_CONTROL_MODE,
        robot_init_qpos_noise: float = DEFAULT_QPOS_NOISE,
        num_envs: int = 1,
        reconfiguration_freq: Optional[int] = None,
        num_levels: int = 0,
        start_level: int = 0,
        sun_pitch_range: Optional[tuple[float, float]] = None,
        camera_jitter: float = 0.0,
        object_scale: float = 1.0,
        object_mass_scale: float = 1.0,
        object_friction: Optional[float] = None,
        gravity_scale: float = 1.0,
        action_delay: Union[None, int, tuple[int, int]] = None,
        observation_delay: Union[None, int, tuple[int, int]] = None,
        delay_drift: float = 0.0,
        mount: Optional[str] = None,
        servicer_mass: Optional[float] = None,
        **kwargs,
    ):
        modes = {key: kwargs[key] for key in ("obs_mode", "reward_mode") if key in kwargs}
        checked = self.check_task_kwargs(
            domain=domain,
            asset_source=asset_source,
            robot_uids=robot_uids,
            control_mode=control_mode,
            robot_init_qpos_noise=robot_init_qpos_noise,
            reconfiguration_freq=reconfiguration_freq,
            num_levels=num_levels,
            start_level=start_level,
            sun_pitch_range=sun_pitch_range,
            camera_jitter=camera_jitter,
            object_scale=object_scale,
            object_mass_scale=object_mass_scale,
            object_friction=object_friction,
            gravity_scale=gravity_scale,
            action_delay=action_delay,
            observation_delay=observation_delay,
            delay_drift=delay_drift,
            mount=mount,
            servicer_mass=servicer_mass,
            **modes,
        )
        self.domain = get_domain(checked["domain"], self.SUPPORTED_DOMAINS)
        self.asset_source = checked["asset_source"]
        self.robot_init_qpos_noise = checked["robot_init_qpos_noise"]
        self.levels_config = LevelRange(checked["num_levels"], checked["start_level"])
        self.factors = FactorShifts.from_checked(checked)
        self.action_delay, self.observation_delay, self.delay_drift = checked["action_delay"], checked["observation_delay"], checked["delay_drift"]
        self._action_line: Optional[DelayLine] = None
        self._observation_line: Optional[DelayLine] = None
        self.levels = np.zeros(num_envs, dtype=np.int64)
        """Each env's level (the seed of its scene's procedural content), drawn at every reconfiguration."""
        self._wrist_wrench_reading: Optional[torch.Tensor] = None
        self.free_flyer = checked["mount"] == "free_flyer"
        """The arm stands on a free-floating servicer (``mount="free_flyer"``), not on the station or rover."""
        self.servicer_mass = checked["servicer_mass"]
        self.mount = self._make_mount()
        reconfiguration_freq = checked["reconfiguration_freq"]
        if reconfiguration_freq is None:
            # Varied geometry: a single (CPU) env rebuilds its objects every episode; parallel envs differ instead.
            reconfiguration_freq = 1 if num_envs == 1 else 0
        super().__init__(
            *args,
            robot_uids=checked["robot_uids"],
            control_mode=checked["control_mode"],
            num_envs=num_envs,
            reconfiguration_freq=reconfiguration_freq,
            **kwargs,
        )

    @classmethod
    def check_task_kwargs(cls, **kwargs) -> dict[str, Any]:
        """Check the env's kwargs without building anything (suites and the command-line tools call this when they
        read a configuration; ``__init__`` calls it too).

        Checks the kwargs of ours, ``domain``, ``asset_source``, ``robot_uids``, ``robot_init_qpos_noise`` and
        ``reconfiguration_freq``, and ManiSkill's ``control_mode`` and, where given, ``obs_mode`` and
        ``reward_mode``. Returns them checked, a missing one or None replaced by its default (``reconfiguration_freq``
        keeps None: every episode rebuilds the scene of a single env, parallel envs never). Other kwargs (ManiSkill's)
        are ignored. A bad value raises a ``KwargError`` (a ``ValueError``) naming the kwarg and its valid choices
        or range. Tasks extend this with their own kwargs."""
        robot_uids = checked_choice("robot_uids", kwargs.get("robot_uids"), tuple(cls.SUPPORTED_ROBOTS), cls.SUPPORTED_ROBOTS[0])
        checked: dict[str, Any] = dict(
            domain=checked_choice("domain", kwargs.get("domain"), cls.SUPPORTED_DOMAINS, cls.DEFAULT_DOMAIN),
            asset_source=checked_choice("asset_source", kwargs.get("asset_source"), cls.SUPPORTED_ASSET_SOURCES, cls.DEFAULT_ASSET_SOURCE),
            robot_uids=robot_uids,
            control_mode=checked_choice("control_mode", kwargs.get("control_mode"), supported_control_modes(robot_uids), DEFAULT_CONTROL_MODE),
            robot_init_qpos_noise=checked_number(
                "robot_init_qpos_noise",
                kwargs.get("robot_init_qpos_noise", DEFAULT_QPOS_NOISE),
                0.0,
                MAX_QPOS_NOISE,
                unit="rad",
                meaning=f"uniform noise on the arm's joints at reset; beyond {MAX_QPOS_NOISE:g} rad the Panda's elbow can start outside its limits",
            ),
            reconfiguration_freq=None
            if kwargs.get("reconfiguration_freq") is None
            else checked_natural("reconfiguration_freq", kwargs["reconfiguration_freq"], "reconfigure every that many resets; 0: never"),
        )
        checked.update(check_level_kwargs(kwargs))
        checked.update(check_delay_kwargs(kwargs))
        if checked["action_delay"].active and not holds_with_a_fixed_action(checked["control_mode"]):
            raise KwargError("action_delay", f"action_delay needs a control mode in which the steps before the first delayed action can hold still: a delta mode or pd_joint_pos, not {checked['control_mode']!r}")
        checked.update(check_factor_kwargs(kwargs, supports_object_scale=cls.SUPPORTS_OBJECT_SCALE, task=cls.__name__))
        checked.update(cls._check_mount_kwargs(kwargs, checked["domain"]))
        if kwargs.get("obs_mode") is not None:
            checked["obs_mode"] = _checked_obs_mode(kwargs["obs_mode"])
        if kwargs.get("reward_mode") is not None:
            checked["reward_mode"] = checked_choice("reward_mode", kwargs["reward_mode"], cls.SUPPORTED_REWARD_MODES)
        return checked

    @classmethod
    def _check_mount_kwargs(cls, kwargs: dict, domain: str) -> dict[str, Any]:
        """``mount`` ("fixed" by default, or "free_flyer": in orbit, for the tasks that support it) and
        ``servicer_mass`` (kg, free flyer only)."""
        mount = checked_choice("mount", kwargs.get("mount"), MOUNTS, MOUNTS[0])
        if mount == "free_flyer":
            if not cls.SUPPORTS_FREE_FLYER:
                supporting = ", ".join(sorted(env.__name__ for env in _subclasses(SpaceManipulationEnv) if env.SUPPORTS_FREE_FLYER))
                raise KwargError("mount", f"{cls.__name__} has no free-flying servicer; mount='free_flyer' applies to: {supporting}")
            if domain != "orbit":
                raise KwargError("mount", f"mount='free_flyer' floats only in orbit (domain='orbit'), not in domain {domain!r}")
        elif kwargs.get("servicer_mass") is not None:
            raise KwargError("servicer_mass", "servicer_mass is the free-flying servicer's mass: it needs mount='free_flyer'")
        try:
            mass = check_servicer_mass(kwargs.get("servicer_mass"))
        except ValueError as error:
            raise KwargError("servicer_mass", str(error)) from None
        return dict(mount=mount, servicer_mass=mass)

    # ------------------------------------------------------------------ configuration
    @classmethod
    def nominal_episode_steps(cls) -> int:
        """EPISODE_SECONDS in control steps (the registered time limit)."""
        return round(cls.EPISODE_SECONDS * cls.CONTROL_FREQ)

    @property
    def _default_sim_config(self):
        return SimConfig(
            sim_freq=self.SIM_FREQ,
            control_freq=self.CONTROL_FREQ,
            spacing=ENV_SPACING,
            scene_config=SceneConfig(gravity=np.asarray(self.domain.gravity_vector) * self.factors.gravity_scale),
            default_materials_config=DefaultMaterialsConfig(static_friction=1.0, dynamic_friction=1.0, restitution=0.0),
            gpu_memory_config=GPUMemoryConfig(
                max_rigid_contact_count=max(2**19, self.num_envs * 2**12),
                max_rigid_patch_count=max(2**18, self.num_envs * 2**11),
            ),
        )

    @property
    def _default_sensor_configs(self):
        base_camera = dict(pose=self._base_camera_pose())
        if self.free_flyer:  # the base camera rides the servicer: its pose in the bus's frame (the arm's mount)
            base_camera = dict(pose=Pose.create(sapien.Pose(self.mount.frames["arm_mount"]).inv()) * Pose.create(base_camera["pose"]), mount=self.agent.robot.links_map[BUS_LINK])
        return [
            CameraConfig("base_camera", width=SENSOR_SIZE, height=SENSOR_SIZE, fov=np.deg2rad(90), near=0.01, far=SENSOR_FAR, **base_camera),
            CameraConfig(
                "wrist_camera",
                sapien.Pose(look_at(WRIST_CAMERA_EYE, WRIST_CAMERA_TARGET, up=(1.0, 0.0, 0.0))),
                SENSOR_SIZE,
                SENSOR_SIZE,
                np.deg2rad(80),
                0.01,
                SENSOR_FAR,
                mount=self.agent.tcp,
            ),
        ]

    @property
    def _default_human_render_camera_configs(self):
        return CameraConfig("render_camera", sapien.Pose(self._render_camera_pose()), 512, 512, 1.0, 0.01, SENSOR_FAR + 5)

    def _base_camera_pose(self):
        """The mount's base camera; with ``camera_jitter`` one pose per env, its eye and the point it looks at
        each moved by that env's offsets (drawn at reconfiguration from the episode seed: ManiSkill's way of
        varying a camera per sub-scene)."""
        frame = self.mount.frames["base_camera"]
        offsets = getattr(self, "_camera_offsets", None)
        if offsets is None:
            return sapien.Pose(frame)
        poses = [sapien.Pose(matrix) for matrix in jittered_camera_frames(frame, offsets)]
        return Pose.create_from_pq(torch.tensor(np.stack([p.p for p in poses])), torch.tensor(np.stack([p.q for p in poses])))

    def _render_camera_pose(self) -> np.ndarray:
        return look_at((1.3, -1.05, 0.95), (-0.1, 0.0, 0.25))

    # ------------------------------------------------------------------ scene
    def _make_mount(self) -> Asset:
        raise NotImplementedError

    def _load_agent(self, options: dict):
        if not self.free_flyer:
            super()._load_agent(options, sapien.Pose(self.mount.frames["arm_mount"]))
            return
        from mani_skill_space.envs.servicer import servicer_agent_class

        # ManiSkill's _load_agent for one agent, with the arm on the servicer's free-floating bus
        agent_class = servicer_agent_class(REGISTERED_AGENTS[self.robot_uids].agent_cls, self.servicer_mass)
        self.agent = agent_class(self.scene, self._control_freq, self._control_mode, initial_pose=sapien.Pose(self.mount.frames["arm_mount"]))

    def _load_domain_scene(self):
        """Mount, sky, ground and the sun's direction for every env (call first in ``_load_scene``)."""
        self._graspable_radius: dict[str, float] = {}
        self._draw_levels()
        # a free-flying servicer leaves the station behind (its frames still place the arm, cameras and objects)
        self.mount_actor = None if self.free_flyer else build_asset_actor(self.scene, self.mount, "mount", body_type="static")
        pitch = self.factors.sun_pitch_range
        self._sun_directions = [sample_sun_direction(np.random.default_rng(s), pitch_range_deg=pitch) for s in self._asset_seeds()]
        self._camera_offsets = camera_offsets(self._episode_seed, self.factors.camera_jitter)
        if self.scene.can_render():
            self.skydome = build_skydome(self.scene, str(sky_texture_path(self.domain.sky)))
        if self.domain.terrain is not None:
            terrains = [make_terrain(s, self.domain.terrain) for s in self._asset_seeds()]
            self.ground = build_actor_per_env(self.scene, terrains, "terrain", body_type="static")
        elif self.domain.ground_texture is not None:
            self.ground = build_flat_ground(self.scene, make_flat_ground(self.domain.ground_texture))
        else:
            self.ground = None

    def _draw_levels(self):
        """Each env's level for this reconfiguration (``LevelRange.draw``), and the RNG its content comes from."""
        self.levels = self.levels_config.draw(self._episode_seed, self._batched_episode_rng)
        self._level_rng = BatchedRNG.from_seeds(self.levels, backend=self._batched_rng_backend)

    def _asset_seeds(self) -> np.ndarray:
        """One fresh seed per env from its level's RNG: every call in a reconfiguration draws the next (sun,
        terrain, then the task's objects), so the scene's procedural content is a function of the level alone."""
        return self._level_rng.randint(0, 2**31 - 1)

    def _load_lighting(self, options: dict):
        self.scene.set_ambient_light(self.domain.ambient_color.tolist())
        for i, direction in enumerate(self._sun_directions):
            self.scene.add_directional_light(
                direction.tolist(), self.domain.sun_color.tolist(), shadow=self.enable_shadow, shadow_scale=3.0, scene_idxs=[i]
            )

    def _initialize_agent(self, env_idx: torch.Tensor):
        """Rest keyframe plus per-env uniform joint noise (arm joints only; the gripper starts open)."""
        b = len(env_idx)
        rest = torch.as_tensor(self.agent.keyframes["rest"].qpos, dtype=torch.float32, device=self.device)
        noise = self._batched_episode_rng[env_idx].uniform(-1.0, 1.0, size=(rest.shape[0],)) * self.robot_init_qpos_noise
        qpos = rest.repeat(b, 1) + torch.as_tensor(noise, dtype=torch.float32, device=self.device).reshape(b, -1)
        qpos[:, self._gripper_joint_indices] = rest[self._gripper_joint_indices]
        self.agent.reset(qpos)
        self.agent.robot.set_pose(sapien.Pose(self.mount.frames["arm_mount"]))
        if self.free_flyer:  # the servicer starts at rest
            self.agent.robot.set_root_linear_velocity(torch.zeros((b, 3), device=self.device))
            self.agent.robot.set_root_angular_velocity(torch.zeros((b, 3), device=self.device))
        self._previous_action[env_idx] = 0.0
        self._current_action[env_idx] = 0.0

    def _after_reconfigure(self, options: dict):
        action_dim = self.agent.single_action_space.shape[0]
        self._previous_action = torch.zeros((self.num_envs, action_dim), device=self.device)
        self._current_action = torch.zeros((self.num_envs, action_dim), device=self.device)
        gripper = self.agent.controller.controllers["gripper"]
        self._gripper_joint_indices = gripper.active_joint_indices.to(self.device)
        arm_joints = self.agent.controller.controllers["arm"].joints
        self._arm_link_names = [joint.child_link.name for joint in arm_joints]
        mount = torch.as_tensor(self.mount.frames["arm_mount"], dtype=torch.float32, device=self.device)
        self._arm_base_position = mount[:3, 3].expand(self.num_envs, 3)
        self._arm_base_rotation = mount[:3, :3].expand(self.num_envs, 3, 3)
        self._wrist_link_index = int(torch.as_tensor(gripper.joints[0].parent_link.index).flatten()[0])
        self._action_line = DelayLine(self.num_envs, self.action_delay, self.device) if self.action_delay.active else None
        self._observation_line = DelayLine(self.num_envs, self.observation_delay, self.device) if self.observation_delay.active else None

    def _clear(self):
        """ManiSkill's ``_clear`` (drop the scene, agent, sensors), with its full garbage collection only on the GPU
        simulator, on ``close`` and at every ``FULL_COLLECTION_EVERY``-th rebuild on the CPU."""
        self._rebuilds_since_collection = getattr(self, "_rebuilds_since_collection", 0) + 1
        on_gpu = self.backend.sim_backend != "physx_cpu"
        if on_gpu or getattr(self, "_closing", False) or self._rebuilds_since_collection >= FULL_COLLECTION_EVERY:
            self._rebuilds_since_collection = 0
            super()._clear()
            return
        # ManiSkill 3.0.1's BaseEnv._clear without its gc.collect()
        self._close_viewer()
        self.agent = None
        self._sensors = dict()
        self._human_render_cameras = dict()
        self.scene = None
        self._hidden_objects = []

    def close(self):
        self._closing = True
        super().close()

    # ------------------------------------------------------------------ communication delay
    def reset(self, seed=None, options=None):
        """ManiSkill's reset; with a communication delay, the reset envs also draw their delays (from the episode
        seed) and forget what was sent before."""
        obs, info = super().reset(seed=seed, options=options)
        if self._action_line is not None or self._observation_line is not None:
            env_idx = (options or {}).get("env_idx")
            env_idx = torch.arange(self.num_envs, device=self.device) if env_idx is None else torch.as_tensor(env_idx, device=self.device)
            rng = self._batched_episode_rng[env_idx]
            for line, first in ((self._action_line, None), (self._observation_line, obs)):
                if line is not None:
                    line.reset(env_idx, torch.as_tensor(rng.randint(line.delays.low, line.delays.high + 1)), first)
        return obs, info

    def step(self, action):
        """ManiSkill's step with the communication delay: the action applied is the one sent ``action_delay``
        steps ago (before any was, one that holds still: zero for delta modes, the current targets otherwise), the
        observation returned the one of ``observation_delay`` steps ago (the reset observation before that).
        Reward, termination and info are computed from the simulation now, undelayed."""
        if self._action_line is not None and action is not None:
            self._action_line.push(torch.as_tensor(action, dtype=torch.float32, device=self.device).reshape(self.num_envs, -1))
            delayed, missing = self._action_line.read()
            action = with_missing_replaced(delayed, missing, self.hold_action())
        obs, reward, terminated, truncated, info = super().step(action)
        if self._observation_line is not None:
            self._observation_line.push(obs)
            obs, _ = self._observation_line.read()
        if self.delay_drift > 0:
            for line in (self._action_line, self._observation_line):
                if line is not None:
                    line.drift(drift_moves(torch.as_tensor(self._batched_episode_rng.uniform(0.0, 1.0)), self.delay_drift))
        return obs, reward, terminated, truncated, info

    def hold_action(self) -> torch.Tensor:
        """(num_envs, action_dim): the action that leaves the robot as it is commanded now (zero for delta
        controllers; the current joint targets, in action units, for joint-position ones such as the gripper's)."""
        return torch.cat([hold_action_of(controller, self.num_envs) for controller in self.agent.controller.controllers.values()], dim=-1).to(self.device)

    # ------------------------------------------------------------------ step
    def _step_action(self, action):
        action = super()._step_action(action)
        if isinstance(action, torch.Tensor):
            low, high = self._action_bounds()
            current = torch.clamp(action.float().reshape(self.num_envs, -1), low, high)
            if current.shape != self._current_action.shape:  # the control mode was switched through the action
                self._current_action = torch.zeros_like(current)
            self._previous_action, self._current_action = self._current_action, current
        self._update_task_state()
        return action

    def _update_task_state(self):
        """Runs once per control step, after the physics (and, on the GPU, after fetching its state): tasks
        that track history (e.g. how long an object has been held still) update it here."""

    def _action_bounds(self) -> tuple[torch.Tensor, torch.Tensor]:
        space = self.agent.single_action_space
        return (torch.as_tensor(space.low, device=self.device), torch.as_tensor(space.high, device=self.device))

    def get_info(self) -> dict:
        info = super().get_info()
        inputs = {**self._reward_inputs(info), **self._penalty_inputs()}
        info["reward_terms"] = self.REWARD_TABLE.weighted(inputs)
        return info

    def _penalty_inputs(self) -> dict[str, torch.Tensor]:
        low, high = self._action_bounds()
        forces = self.agent.robot.get_net_contact_forces(self._arm_link_names)
        return {
            "action_rate": action_rate(self._current_action, self._previous_action, low, high),
            "arm_contact": (torch.linalg.norm(forces, dim=-1).amax(dim=-1) > ARM_CONTACT_LIMIT).float(),
        }

    def _reward_inputs(self, info: dict) -> dict[str, torch.Tensor]:
        raise NotImplementedError

    def compute_dense_reward(self, obs: Any, action: torch.Tensor, info: dict) -> torch.Tensor:
        """The sum of the weighted terms ``get_info`` reported; success gives the table's maximum."""
        return self.REWARD_TABLE.dense(info["reward_terms"], info["success"])

    def compute_normalized_dense_reward(self, obs: Any, action: torch.Tensor, info: dict) -> torch.Tensor:
        return self.REWARD_TABLE.normalize(self.compute_dense_reward(obs, action, info))

    def build_graspable(self, assets: list[Asset], name: str, never_sleep: bool = False):
        """The per-env dynamic object made of ``assets`` (``building.build_dynamic_per_env``) with the material factor
        shifts applied (``object_mass_scale``, ``object_friction``; tasks with ``object_scale`` scale their assets
        with ``self.factors.scaled`` before), remembered with its
        bounding radius so that ``is_grasping`` can skip its contact query when it is out of the fingers' reach.
        ``never_sleep``: PhysX never puts it to sleep, however slowly it moves (in zero gravity a slow drift is
        real motion, e.g. of a part let go in orbit). It is solved with ``GRASPABLE_SOLVER_POSITION_ITERATIONS``."""
        assets = [self.factors.with_material(asset) for asset in assets]
        actor = build_dynamic_per_env(self.scene, assets, name)
        iterations = max(GRASPABLE_SOLVER_POSITION_ITERATIONS, self.sim_config.scene_config.solver_position_iterations)
        for body in actor._bodies:
            body.solver_position_iterations = iterations
            if never_sleep:
                body.sleep_threshold = 0.0
        self._graspable_radius[name] = bounding_radius(assets)
        return actor

    def is_grasping(self, actor) -> torch.Tensor:
        """ManiSkill's Panda grasp check (both fingers press on ``actor``, reference forces and angles). On the CPU
        simulator, where each check scans every contact of the scene, an object built with ``build_graspable``
        that is out of the fingers' reach in every env is not grasped without asking (the answer is the same)."""
        radius = self._graspable_radius.get(actor.name)
        if radius is not None and not self.gpu_sim_enabled:
            distance = torch.linalg.norm(actor.pose.p - self.agent.tcp.pose.p, dim=-1)
            if bool((distance > radius + FINGER_REACH).all()):
                return torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        return self.agent.is_grasping(actor, min_force=GRASP_MIN_FORCE)

    # ------------------------------------------------------------------ observations
    def tcp_frame(self) -> tuple[torch.Tensor, torch.Tensor]:
        """World position (n, 3) and rotation matrix (n, 3, 3) of the TCP."""
        pose = self.agent.tcp.pose
        return pose.p, rotation_matrix(pose.q)

    def _get_obs_extra(self, info: dict) -> dict[str, torch.Tensor]:
        """Observations every task shares; tasks extend this with ``super()._get_obs_extra(info)``."""
        return self._shared_obs_extra(*self.tcp_frame())

    def arm_base_frame(self) -> tuple[torch.Tensor, torch.Tensor]:
        """World position (n, 3) and rotation (n, 3, 3) of the arm's base: fixed on the station or rover, the
        servicer bus's moving frame (the centre of its top face) on a free flyer."""
        if not self.free_flyer:
            return self._arm_base_position, self._arm_base_rotation
        pose = self.agent.robot.pose
        return pose.p, rotation_matrix(pose.q)

    def _shared_obs_extra(self, tcp_position: torch.Tensor, tcp_rotation: torch.Tensor) -> dict[str, torch.Tensor]:
        position, rotation = relative_pose(*self.arm_base_frame(), tcp_position, tcp_rotation)
        obs = dict(
            tcp_pos=position,
            tcp_rot6d=rotation_6d(rotation),
            gripper_opening=self.gripper_opening().unsqueeze(-1),
            time_remaining=self.time_remaining().unsqueeze(-1),
        )
        if self.obs_mode_struct.use_state:
            obs["wrist_wrench"] = self.wrist_wrench()
            if self.free_flyer:  # where the servicer has drifted and turned from its start, and how fast
                robot = self.agent.robot
                obs.update(
                    servicer_pos=robot.pose.p - self._arm_base_position,
                    servicer_quat=robot.pose.q,
                    servicer_linear_velocity=robot.root_linear_velocity,
                    servicer_angular_velocity=robot.root_angular_velocity,
                )
        return obs

    def gripper_opening(self) -> torch.Tensor:
        """Mean finger opening in [0, 1] (0 = closed, 1 = open), from the gripper joints' limits."""
        qpos = self.agent.robot.get_qpos()[:, self._gripper_joint_indices]
        limits = self.agent.robot.get_qlimits()[:, self._gripper_joint_indices]
        return ((qpos - limits[..., 0]) / (limits[..., 1] - limits[..., 0])).mean(dim=-1)

    def time_remaining(self) -> torch.Tensor:
        """Fraction of the episode left, from the elapsed steps (which the env's state carries)."""
        return 1.0 - self.elapsed_steps.float() / self._episode_step_limit()

    def steps_remaining(self) -> torch.Tensor:
        """Control steps left in the episode, per env."""
        return self._episode_step_limit() - self.elapsed_steps

    def _episode_step_limit(self) -> int:
        return self.spec.max_episode_steps if getattr(self, "spec", None) is not None and self.spec.max_episode_steps else self.nominal_episode_steps()

    def wrist_wrench(self) -> torch.Tensor:
        """Spatial force (force, torque) the wrist joint transmitted to the hand in the last physics step: what a
        wrist F/T sensor measures. Read after every control step and kept with the env's state (the simulation
        state cannot restore forces); zero at the start of an episode, before any physics step."""
        return self._wrist_wrench_buffer().clone()

    def _wrist_wrench_buffer(self) -> torch.Tensor:
        """The (num_envs, 6) wrench reading, made on first use (the first reset of ``__init__``)."""
        if self._wrist_wrench_reading is None:
            self._wrist_wrench_reading = torch.zeros((self.num_envs, 6), device=self.device)
        return self._wrist_wrench_reading

    # ------------------------------------------------------------------ latches
    def _latch_forces(self) -> list[tuple[Any, torch.Tensor]]:
        """(actor, (num_envs, 3) force) pairs that the task's latches apply at every physics step of the coming
        control step (e.g. a socket holding a seated peg): none by default."""
        return []

    def _before_control_step(self):
        super()._before_control_step()
        # measured once per control step, so that the CPU and GPU simulations (whose poses are fetched once per
        # control step) apply the same forces
        forces = self._latch_forces()
        if not self.gpu_sim_enabled:  # applied body by body on the CPU: leave out the latches that hold nothing
            forces = [(actor, force) for actor, force in forces if bool(force.any())]
        self._pending_latch_forces = forces

    def _before_simulation_step(self):
        super()._before_simulation_step()
        for actor, force in getattr(self, "_pending_latch_forces", ()):
            apply_force(actor, force)

    def _after_control_step(self):
        super()._after_control_step()
        self._wrist_wrench_buffer()[:] = self.agent.robot.get_link_incoming_joint_forces()[:, self._wrist_link_index].to(self.device)

    def _clear_sim_state(self):
        """Also forgets the wrench reading of the envs being reset (the previous episode's last physics step)."""
        super()._clear_sim_state()
        self._wrist_wrench_buffer()[self.scene._reset_mask] = 0.0

    # ------------------------------------------------------------------ state
    def get_state_dict(self) -> dict:
        """ManiSkill's state (simulation and controller) plus, under ``"task"``, what the observation reads besides
        the simulation: the elapsed steps (the remaining time, and what the time limit counts) and the wrist wrench
        of the last physics step. Tasks that track more across steps add their entries to ``"task"``. Every entry
        is a (num_envs, k) float tensor, as ManiSkill's trajectory files store states."""
        state = super().get_state_dict()
        state["task"] = dict(elapsed_steps=self._elapsed_steps[:, None].float(), wrist_wrench=self._wrist_wrench_buffer().clone())
        return state

    def set_state_dict(self, state: dict, env_idx: Optional[torch.Tensor] = None):
        """Restores what ``get_state_dict`` recorded; as in ManiSkill, with ``env_idx`` the state's rows are those
        envs'. A state without the ``"task"`` entries (from ManiSkill's tools, or recorded by an older version)
        restores the simulation and leaves the elapsed steps and the wrench reading as they are."""
        super().set_state_dict(state, env_idx)
        task = self._task_state_of(state)
        rows = slice(None) if env_idx is None else env_idx
        if "elapsed_steps" in task:
            self._elapsed_steps[rows] = task["elapsed_steps"][:, 0].round().to(self._elapsed_steps.dtype)
        if "wrist_wrench" in task:
            self._wrist_wrench_buffer()[rows] = task["wrist_wrench"]

    def set_state(self, state: torch.Tensor, env_idx: Optional[torch.Tensor] = None):
        """Restores a flat ``get_state()`` vector. ManiSkill 3.0.1's version rebuilds only the actors and
        articulations from it and drops the rest of what ``get_state`` flattened; this one cuts the vector along the
        layout of ``get_state_dict()`` (ManiSkill's flattening order), so the flat state restores as much as the dict."""
        state = torch.as_tensor(state, device=self.device)
        state_dict, width = _unflattened_like(self.get_state_dict(), state.reshape(-1, state.shape[-1]))
        if width != state.shape[-1]:
            raise ValueError(f"a flat state of this env has {width} columns (the layout of get_state_dict()), got {state.shape[-1]}")
        self.set_state_dict(state_dict, env_idx)

    def _task_state_of(self, state: dict) -> dict[str, torch.Tensor]:
        """The ``"task"`` entries of a state dict as (rows, k) float tensors on the env's device (none without one);
        as in ManiSkill, a 1-D entry is one env's (a trajectory file's state at one step)."""
        entries = {key: torch.as_tensor(value, device=self.device).float() for key, value in state.get("task", {}).items()}
        return {key: value[None] if value.ndim == 1 else value for key, value in entries.items()}


class RestingPlacement:
    """Each env's object on flat ground, at rest: statically stable faces (``procgen.resting``), batched."""

    def __init__(self, assets: list[Asset], device, exclude_axis: Optional[np.ndarray] = None):
        self.points = padded_points([a.collision_vertices for a in assets], device)
        rests = [resting_orientations(a.collision_vertices, exclude_axis=exclude_axis) for a in assets]
        self.counts = torch.tensor([len(r) for r in rests], device=device)
        self.quaternions = padded_points(rests, device)
        self.allowed = torch.arange(self.quaternions.shape[1], device=device)[None, :] < self.counts[:, None]
        """(n, faces): the faces ``face_down`` picks from (all stable faces unless ``allow_only`` narrowed them)."""

    def allow_only(self, faces: torch.Tensor) -> None:
        """Let ``face_down`` pick only among ``faces`` (n, faces) of each env's stable faces; every env must keep one."""
        allowed = self.allowed & faces
        if not bool(allowed.any(dim=1).all()):
            raise ValueError("every env needs at least one allowed resting face")
        self.allowed = allowed

    def rotations(self, env: int = 0) -> torch.Tensor:
        """(F, 3, 3): one env's resting rotations (object to world, lying on each of its real faces)."""
        return quaternion_to_matrix(self.quaternions[env, : int(self.counts[env])])

    def face_down(self, env_idx: torch.Tensor, uniform) -> torch.Tensor:
        """wxyz orientations (b, 4) putting a stable (allowed) face down, picked by ``uniform`` draws in [0, 1)."""
        allowed = self.allowed[env_idx]
        counts = allowed.sum(dim=1)
        pick = (torch.as_tensor(uniform, dtype=torch.float32, device=counts.device) * counts).long().clamp(max=counts - 1)
        face = ((allowed.cumsum(dim=1) - 1 == pick[:, None]) & allowed).int().argmax(dim=1)
        return self.quaternions[env_idx, face]

    def height_on_ground(self, env_idx: torch.Tensor, quaternion: torch.Tensor, clearance: float) -> torch.Tensor:
        """Height (b,) of the object's origin that puts its lowest point ``clearance`` above z = 0."""
        lowest = torch.einsum("bij,bnj->bni", quaternion_to_matrix(quaternion), self.points[env_idx])[..., 2].amin(dim=1)
        return clearance - lowest


def apply_force(actor, force: torch.Tensor) -> None:
    """Apply ``force`` (num_envs, 3), in Newtons at the centre of mass, to a per-env actor for the next physics
    step: ManiSkill's ``Actor.apply_force`` on the GPU; body by body on the CPU (where it takes one vector)."""
    if actor.scene.gpu_sim_enabled:
        actor.apply_force(force)
        return
    for body, body_force in zip(actor._bodies, force.cpu().numpy()):
        body.add_force_at_point(force=body_force, point=(body.entity_pose * body.cmass_local_pose).p)


def turned_about_z(quaternion: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
    """``quaternion`` (b, 4, wxyz) followed by a turn of ``yaw`` (b,) about the world z axis."""
    half = yaw / 2
    zeros = torch.zeros_like(half)
    return quaternion_multiply(torch.stack([torch.cos(half), zeros, zeros, torch.sin(half)], dim=-1), quaternion)


class SocketClearance:
    """The ``clearance`` kwarg of the tasks whose procedural sockets are cut around their pegs (a mixin before
    ``SpaceManipulationEnv``): checked by ``socket_clearance`` with the task's generator's ``CLEARANCE_CHECK``, kept
    as ``self.clearance``."""

    CLEARANCE_CHECK: ClassVar[Callable[[Any], float]] = staticmethod(check_clearance)

    def __init__(self, *args, clearance: Optional[float] = None, asset_source: Optional[str] = None, **kwargs):
        self.clearance = self.check_task_kwargs(clearance=clearance, asset_source=asset_source)["clearance"]
        super().__init__(*args, asset_source=asset_source, **kwargs)

    @classmethod
    def check_task_kwargs(cls, **kwargs) -> dict:
        """The base class's checks, and ``clearance``: procedural sockets only, positive and at most what the
        generator's sockets hold (``CLEARANCE_CHECK``)."""
        checked = super().check_task_kwargs(**kwargs)
        checked["clearance"] = socket_clearance(kwargs.get("clearance"), checked["asset_source"], cls.CLEARANCE_CHECK)
        return checked


def _subclasses(cls: type) -> list[type]:
    return [sub for direct in cls.__subclasses__() for sub in (direct, *_subclasses(direct))]


def socket_clearance(clearance: Any, asset_source: str, check: Callable[[Any], float] = check_clearance) -> float:
    """The ``clearance`` kwarg of the tasks with procedurally cut sockets, checked: it applies to procedural assets
    only (the dataset sockets have a fixed 1 mm); ``check`` (the procedural generator's) accepts it if it is positive
    and at most what the generated sockets hold; None gives the default (1 mm)."""
    if clearance is not None and asset_source == "dataset":
        raise KwargError("clearance", "clearance applies to procedural assets only; the dataset sockets have a fixed 1 mm clearance")
    return DEFAULT_CLEARANCE if clearance is None else check(clearance)


def _unflattened_like(template: dict, flat: torch.Tensor, start: int = 0) -> tuple[dict, int]:
    """``flat``'s columns from ``start`` cut into a dict shaped like ``template`` (nested dicts of (n, k) or (n,)
    tensors), in the order ManiSkill's ``flatten_state_dict`` joins them; also the column after the last one used."""
    result = {}
    for key, value in template.items():
        if isinstance(value, dict):
            result[key], start = _unflattened_like(value, flat, start)
        else:
            width = 1 if value.ndim == 1 else value.shape[-1]
            result[key] = flat[:, start : start + width]
            start += width
    return result, start


def holds_with_a_fixed_action(control_mode: str) -> bool:
    """Whether ``hold_action_of`` knows the hold action of every controller of ``control_mode``."""
    return "delta" in control_mode or control_mode == "pd_joint_pos"


def hold_action_of(controller, num_envs: int) -> torch.Tensor:
    """The action (num_envs, dim) that keeps one of ManiSkill's controllers where it is commanded now."""
    dim = controller.single_action_space.shape[0]
    if getattr(controller.config, "use_delta", False):
        return torch.zeros((num_envs, dim))
    target = controller._target_qpos
    if hasattr(controller, "control_joint_indices"):  # a mimic controller (the gripper): one action per control joint
        target = target[:, controller.control_joint_indices]
    if getattr(controller, "_normalize_action", False):
        target = inv_scale_action(target, controller.action_space_low, controller.action_space_high)
    return target.reshape(num_envs, dim).float().cpu()


@lru_cache
def supported_control_modes(robot_uid: str) -> tuple[str, ...]:
    """The control modes of a registered ManiSkill robot, without building it: its controller configurations are
    made from class attributes alone (``tests/test_inputs.py`` checks them against a built agent's)."""
    agent_class = REGISTERED_AGENTS[robot_uid].agent_cls
    return tuple(agent_class._controller_configs.fget(object.__new__(agent_class)))


def _checked_obs_mode(obs_mode: Any) -> str:
    """An observation mode ManiSkill accepts: a named mode or textures joined by ``+`` (its own parser's rule)."""
    named = ("state", "state_dict", "none", "sensor_data", "rgbd", "pointcloud")
    try:
        if not isinstance(obs_mode, str):
            raise TypeError(obs_mode)
        parse_obs_mode_to_struct(obs_mode)
    except (AssertionError, TypeError):
        raise KwargError(
            "obs_mode", f"unknown obs_mode {obs_mode!r}; valid choices: {', '.join(named)}, or textures ({', '.join(ALL_VISUAL_TEXTURES)}) joined by '+', optionally with state"
        ) from None
    return obs_mode
