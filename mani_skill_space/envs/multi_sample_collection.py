import numpy as np
import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.pose import Pose

from mani_skill_space.envs.base import PENALTY_TERMS, SpaceManipulationEnv, turned_about_z
from mani_skill_space.envs.sample_collection import LIFT_BAND, RESTING_SPEED, SAMPLE_DROP_CLEARANCE, SAMPLE_X_RANGE, RoverWithSampleBin
from mani_skill_space.envs.sample_collection import REWARD_TABLE as SINGLE_SAMPLE_TABLE
from mani_skill_space.geometry import in_open_box, relative_pose, rotation_6d, rotation_matrix
from mani_skill_space.rewards import RewardTable, RewardTerm, band_distance

SAMPLE_COUNT = 3
LANE_Y = (0.15, 0.0, -0.15)
"""Each sample lies in its own lane across the ground in front of the arm (y of the lane's centre, arm frame)."""
LANE_JITTER = 0.02
TUBE_HEADING_SPREAD = np.pi / 6
"""Tubes lie within 30 degrees of pointing away from the arm, so that two in neighbouring lanes never overlap."""
SAMPLE_TERMS = tuple(term for term in SINGLE_SAMPLE_TABLE.terms if term.weight > 0)
"""Sample Collection's terms (reach, grasp, lift, transport), for the uncollected sample furthest along."""
SAMPLE_VALUE = sum(term.weight for term in SAMPLE_TERMS)

REWARD_TABLE = RewardTable(
    (
        RewardTerm("samples_collected", SAMPLE_COUNT * SAMPLE_VALUE),
        *SAMPLE_TERMS,
        *PENALTY_TERMS,
    )
)


@register_env("MultiSampleCollection-v1", max_episode_steps=450)
class MultiSampleCollectionEnv(RoverWithSampleBin, SpaceManipulationEnv):
    """
    **Task Description:**
    Sample Collection with three samples: a Panda arm on a planetary rover picks three geological samples (rocks,
    or sealed sample tubes) off the ground in front of the rover, one after the other, and drops each into the
    cargo bin on the rover's rear deck. Domains: moon, mars, earth, asteroid. 22.5 s episodes (7.5 s per sample):
    450 control steps at 20 Hz, physics at 100 Hz.

    **Randomizations:**
    - the samples (during reconfiguration, three per parallel env, each from its own asset seed):
      `asset_source="procedural"` gives procedural rocks in the domain's rock flavour, `asset_source="dataset"`
      three sample tubes
    - the terrain around the rover and the sun direction (during reconfiguration)
    - each sample's position: its own lane across the ground in front of the arm (y = 0.15, 0 or -0.15 m
      +- 0.02 m), x in [0.45, 0.65] m, resting on a random statically stable face (tubes: lying flat, within 30
      degrees of pointing away from the arm; rocks: any heading)
    - the arm's initial joint positions: rest pose plus uniform noise of +-`robot_init_qpos_noise` rad

    **Success Conditions:**
    - every sample's centre of mass is inside the bin's inner volume (below its rim), released and resting
      (speed below 0.1 m/s)

    **Reward:** staged, so that progress is monotone: 77 per collected sample (`samples_collected`: in the bin,
    released and resting) plus Sample Collection's terms (reach, grasp, lift, transport; at most 77 together) for
    the uncollected sample whose terms add up to the most, and the shared penalties; success gives the maximum
    (308). `info["stage"]` is the number of samples collected (3 = success). `normalized_dense` maps [-1.5, 308]
    onto [0, 1].
    """

    SUPPORTED_DOMAINS = ("moon", "mars", "earth", "asteroid")
    DEFAULT_DOMAIN = "mars"
    EPISODE_SECONDS = 7.5 * SAMPLE_COUNT
    REWARD_TABLE = REWARD_TABLE
    SUPPORTS_OBJECT_SCALE = True

    def _load_scene(self, options: dict):
        self._load_domain_scene()
        self.samples, self._placements = [], []
        for i in range(SAMPLE_COUNT):
            assets = self._sample_assets()
            self.samples.append(self.build_graspable(assets, f"sample_{i}"))
            self._placements.append(self._sample_placement(assets))
        self._load_bin()

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        with torch.device(self.device):
            b = len(env_idx)
            rng = self._batched_episode_rng[env_idx]
            self._initialize_agent(env_idx)
            heading_spread = TUBE_HEADING_SPREAD if self.asset_source == "dataset" else np.pi
            for sample, placement, lane in zip(self.samples, self._placements, LANE_Y):
                xy = np.stack([rng.uniform(*SAMPLE_X_RANGE), lane + rng.uniform(-LANE_JITTER, LANE_JITTER)], axis=-1)
                resting = placement.face_down(env_idx, rng.uniform(0.0, 1.0))
                quat = turned_about_z(resting, torch.as_tensor(rng.uniform(-heading_spread, heading_spread), dtype=torch.float32))
                position = torch.zeros((b, 3))
                position[:, :2] = torch.as_tensor(xy, dtype=torch.float32)
                position[:, 2] = placement.height_on_ground(env_idx, quat, SAMPLE_DROP_CLEARANCE)
                sample.set_pose(Pose.create_from_pq(position, quat))
            self._sample_start_height[env_idx] = torch.stack([sample.pose.p[env_idx, 2] for sample in self.samples], dim=1)

    def _after_reconfigure(self, options: dict):
        super()._after_reconfigure(options)
        self._sample_start_height = torch.zeros((self.num_envs, SAMPLE_COUNT), device=self.device)

    def sample_positions(self) -> torch.Tensor:
        """(num_envs, 3 samples, 3)."""
        return torch.stack([sample.pose.p for sample in self.samples], dim=1)

    def evaluate(self):
        positions = self.sample_positions()
        in_bin = in_open_box(positions, self._bin_floor, self._bin_half_size)
        grasped = torch.stack([self.is_grasping(sample) for sample in self.samples], dim=1)
        resting = torch.stack([torch.linalg.norm(sample.linear_velocity, dim=-1) < RESTING_SPEED for sample in self.samples], dim=1)
        collected = in_bin & ~grasped & resting
        stage = collected.sum(dim=1)
        return dict(
            success=stage == SAMPLE_COUNT,
            stage=stage,
            collected=collected,
            in_bin=in_bin,
            grasped=grasped,
            is_grasped=grasped.any(dim=1),
        )

    def _get_obs_extra(self, info: dict):
        tcp_position, tcp_rotation = self.tcp_frame()
        obs = self._shared_obs_extra(tcp_position, tcp_rotation)
        obs["grasped"] = info["grasped"].float()
        obs["collected"] = info["collected"].float()
        if self.obs_mode_struct.use_state:
            n = self.num_envs
            poses = torch.stack([sample.pose.raw_pose for sample in self.samples], dim=1)
            position, rotation = relative_pose(tcp_position[:, None], tcp_rotation[:, None], poses[..., :3], rotation_matrix(poses[..., 3:]))
            obs.update(
                samples_pos_in_tcp=position.reshape(n, -1),
                samples_rot6d_in_tcp=rotation_6d(rotation).reshape(n, -1),
                samples_to_bin=(self.bin_target[:, None] - poses[..., :3]).reshape(n, -1),
                samples_height=poses[..., 2] - self._sample_start_height,
            )
        return obs

    def _reward_inputs(self, info: dict) -> dict[str, torch.Tensor]:
        """Sample Collection's term inputs for the uncollected sample whose terms add up to the most."""
        positions = self.sample_positions()
        inputs = dict(
            reach=torch.linalg.norm(self.agent.tcp.pose.p[:, None] - positions, dim=-1),
            grasp=info["grasped"].float(),
            lift=band_distance(positions[..., 2] - self._sample_start_height, *LIFT_BAND),
            transport=torch.linalg.norm(positions - self.bin_target[:, None], dim=-1),
        )
        progress = sum(term(inputs[term.name]) for term in SAMPLE_TERMS).masked_fill(info["collected"], -1.0)
        best = progress.argmax(dim=1)
        rows = torch.arange(self.num_envs, device=self.device)
        chosen = {name: value[rows, best] for name, value in inputs.items()}
        every_collected = info["collected"].all(dim=1)
        resting = dict(reach=torch.zeros_like(chosen["reach"]), grasp=torch.zeros_like(chosen["grasp"]), lift=torch.zeros_like(chosen["lift"]), transport=torch.zeros_like(chosen["transport"]))
        chosen = {name: torch.where(every_collected, resting[name], value) for name, value in chosen.items()}
        return dict(samples_collected=info["collected"].float().mean(dim=1), **chosen)
