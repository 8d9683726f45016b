import numpy as np
import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.pose import Pose

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.envs.base import PENALTY_TERMS, RestingPlacement, SpaceManipulationEnv, turned_about_z
from mani_skill_space.geometry import in_open_box, relative_pose, rotation_6d, rotation_matrix
from mani_skill_space.procgen.mounts import make_rover
from mani_skill_space.procgen.rock import make_rock
from mani_skill_space.rewards import RewardTable, RewardTerm, band_distance

SAMPLE_X_RANGE = (0.45, 0.65)
SAMPLE_Y_RANGE = (-0.2, 0.2)
"""Sample position on the ground, arm frame. The reference's 0.55 +- 0.2 x +-0.3 m reaches beyond what a Panda
mounted 0.25 m above the ground can grasp top-down, so the ranges are narrowed to its reachable workspace."""
SAMPLE_DROP_CLEARANCE = 0.0005
LIFT_BAND = (0.25, 0.75)
RESTING_SPEED = 0.1
"""A sample moving slower than this (m/s) counts as resting in the bin."""

REWARD_TABLE = RewardTable(
    (
        RewardTerm("reach", 1.0, sigma=0.25),
        RewardTerm("grasp", 4.0),
        RewardTerm("lift", 8.0, sigma=0.1),
        RewardTerm("transport", 64.0, sigma=0.333),
        *PENALTY_TERMS,
    )
)


class RoverWithSampleBin:
    """What Sample Collection and Multi-Sample Collection share: the rover, the samples' assets, the cargo bin."""

    def _make_mount(self):
        return make_rover()

    def _sample_assets(self) -> list:
        """One sample per env for this rebuild: a procedural rock of the domain's flavour from the next asset seeds
        (drawn for the sealed tube too, so that every source advances the level's RNG alike), scaled by the
        ``object_scale`` factor."""
        seeds = self._asset_seeds()
        if self.asset_source == "procedural":
            assets = [make_rock(seed, self.domain.rock_flavour) for seed in seeds]
        else:
            assets = [load_dataset_object("sample_tube")] * self.num_envs
        return [self.factors.scaled(asset) for asset in assets]

    def _sample_placement(self, assets: list) -> RestingPlacement:
        # a tube lies flat: it never rests on its end caps
        exclude_axis = np.array([1.0, 0.0, 0.0]) if self.asset_source == "dataset" else None
        return RestingPlacement(assets, self.device, exclude_axis=exclude_axis)

    def _load_bin(self):
        bin_frame = self.mount.frames["bin"]
        self._bin_floor = torch.as_tensor(bin_frame[:3, 3], dtype=torch.float32, device=self.device)
        self._bin_half_size = torch.as_tensor(self.mount.info["bin_inner_half_size"], dtype=torch.float32, device=self.device)

    @property
    def bin_target(self) -> torch.Tensor:
        """Centre of the bin's inner volume, world frame, (num_envs, 3)."""
        centre = self._bin_floor + torch.tensor([0.0, 0.0, 1.0], device=self.device) * self._bin_half_size[2]
        return centre.expand(self.num_envs, 3)


@register_env("SampleCollection-v1", max_episode_steps=150)
class SampleCollectionEnv(RoverWithSampleBin, SpaceManipulationEnv):
    """
    **Task Description:**
    A Panda arm mounted on a planetary rover picks a geological sample (a rock, or a sealed sample tube) off
    the ground in front of the rover and drops it into the cargo bin on the rover's rear deck, behind the arm.
    Domains: moon, mars, earth, asteroid (gravity, sunlight, sky and terrain follow the domain). 7.5 s episodes:
    150 control steps at 20 Hz, physics at 100 Hz.

    **Randomizations:**
    - the sample (during reconfiguration, one per parallel env): `asset_source="procedural"` gives a
      procedural rock of about 6 x 6 x 4 cm in the domain's rock flavour (density 2000 kg/m^3);
      `asset_source="dataset"` gives the 33 x 170 mm sample tube
    - the terrain around the rover (craters, dunes, boulders) and the sun direction (during reconfiguration)
    - the sample's position on the ground: x in [0.45, 0.65] m, y in [-0.2, 0.2] m in front of the arm base,
      resting on a random statically stable face (tubes: lying flat) with a random heading, so it starts at rest
    - the arm's initial joint positions: rest pose plus uniform noise of +-`robot_init_qpos_noise` rad

    **Success Conditions:**
    - the sample's centre of mass is inside the bin's inner volume (below its rim)
    - the sample is not grasped (released) and resting (speed below 0.1 m/s)

    **Reward:** dense terms (see `REWARD_TABLE`, reported per step in `info["reward_terms"]`): reach
    1 * (1 - tanh(d_tcp_sample / 0.25)), grasp 4 (both fingers pressing > 5 N), lift 8 while the sample is
    0.25-0.75 m above its start height (tanh falloff 0.1 m outside the band), transport
    64 * (1 - tanh(d_sample_bin / 0.333)), penalties -1.4 * action rate and -0.1 per step of arm contact > 10 N;
    success gives the maximum (77). `normalized_dense` maps [-1.5, 77] onto [0, 1]; `sparse` is the success flag.
    """

    SUPPORTED_DOMAINS = ("moon", "mars", "earth", "asteroid")
    DEFAULT_DOMAIN = "mars"
    EPISODE_SECONDS = 7.5
    REWARD_TABLE = REWARD_TABLE
    SUPPORTS_OBJECT_SCALE = True

    def _load_scene(self, options: dict):
        self._load_domain_scene()
        assets = self._sample_assets()
        self.sample = self.build_graspable(assets, "sample")
        self._placement = self._sample_placement(assets)
        self._load_bin()

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        with torch.device(self.device):
            b = len(env_idx)
            rng = self._batched_episode_rng[env_idx]
            self._initialize_agent(env_idx)
            xy = np.stack([rng.uniform(*SAMPLE_X_RANGE), rng.uniform(*SAMPLE_Y_RANGE)], axis=-1)
            resting = self._placement.face_down(env_idx, rng.uniform(0.0, 1.0))
            quat = turned_about_z(resting, torch.as_tensor(rng.uniform(-np.pi, np.pi), dtype=torch.float32))
            position = torch.zeros((b, 3))
            position[:, :2] = torch.as_tensor(xy, dtype=torch.float32)
            position[:, 2] = self._placement.height_on_ground(env_idx, quat, SAMPLE_DROP_CLEARANCE)
            self.sample.set_pose(Pose.create_from_pq(position, quat))
            self._sample_start_height[env_idx] = position[:, 2]

    def _after_reconfigure(self, options: dict):
        super()._after_reconfigure(options)
        self._sample_start_height = torch.zeros(self.num_envs, device=self.device)

    def evaluate(self):
        is_in_bin = in_open_box(self.sample.pose.p, self._bin_floor, self._bin_half_size)
        is_grasped = self.is_grasping(self.sample)
        is_resting = torch.linalg.norm(self.sample.linear_velocity, dim=-1) < RESTING_SPEED
        return dict(
            success=is_in_bin & ~is_grasped & is_resting,
            is_in_bin=is_in_bin,
            is_grasped=is_grasped,
            is_resting=is_resting,
        )

    def _get_obs_extra(self, info: dict):
        tcp_position, tcp_rotation = self.tcp_frame()
        obs = self._shared_obs_extra(tcp_position, tcp_rotation)
        obs["is_grasped"] = info["is_grasped"].float().unsqueeze(-1)
        if self.obs_mode_struct.use_state:
            sample = self.sample.pose
            position, rotation = relative_pose(tcp_position, tcp_rotation, sample.p, rotation_matrix(sample.q))
            obs.update(
                sample_pos_in_tcp=position,
                sample_rot6d_in_tcp=rotation_6d(rotation),
                sample_to_bin=self.bin_target - sample.p,
                sample_height=(sample.p[:, 2] - self._sample_start_height).unsqueeze(-1),
            )
        return obs

    def _reward_inputs(self, info: dict) -> dict[str, torch.Tensor]:
        sample = self.sample.pose.p
        lift = sample[:, 2] - self._sample_start_height
        return dict(
            reach=torch.linalg.norm(self.agent.tcp.pose.p - sample, dim=-1),
            grasp=info["is_grasped"],
            lift=band_distance(lift, *LIFT_BAND),
            transport=torch.linalg.norm(self.bin_target - sample, dim=-1),
        )
