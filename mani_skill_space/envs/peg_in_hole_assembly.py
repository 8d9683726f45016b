from typing import Any, Optional

import numpy as np
import sapien
import torch
from mani_skill.utils.geometry.rotation_conversions import quaternion_to_matrix
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.pose import Pose

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.envs.base import (
    PENALTY_TERMS,
    RestingPlacement,
    SpaceManipulationEnv,
    build_samples,
    socket_clearance,
    turned_about_z,
)
from mani_skill_space.envs.building import build_actor_per_env
from mani_skill_space.geometry import insertion_measures, pose_matrix, relative_pose, rotation_6d, rotation_matrix
from mani_skill_space.procgen.mounts import make_rover, make_station
from mani_skill_space.procgen.peg_hole import make_peg_hole_pair
from mani_skill_space.rewards import RewardTable, RewardTerm, band_distance

MODULE_POSITION = (0.7, 0.0, 0.0)
"""The hole module (or the socket's post) stands here, on the ground or the station's platform: far enough
from the rover that even the 200 mm peg, lying in front of the module, clears the rover's front."""
PEG_DISTANCE = (0.24, 0.28)
"""The peg lies this far in front of the module (toward the arm), as in the reference."""
PEG_LATERAL = 0.05
PEG_HEADING_JITTER = np.pi / 16
"""The peg lies pointing at the arm (its tip, the end that goes in, toward the arm) within this angle, as in
the reference (a fixed heading +- pi/16). Lying across, a grasp of its side would turn the hand's long side
toward the rover's front."""
PEG_DROP_CLEARANCE = 0.0005
INSERTED_FRACTION = 0.9
ALIGNMENT_TOLERANCE = np.radians(5.0)
LIFT_BAND = (0.05, 0.55)

REWARD_TABLE = RewardTable(
    (
        RewardTerm("reach", 1.0, sigma=0.25),
        RewardTerm("grasp", 4.0),
        RewardTerm("lift", 8.0, sigma=0.05),
        RewardTerm("align_axis", 8.0, sigma=0.5),
        RewardTerm("align_twist", 4.0, sigma=0.2),
        RewardTerm("entrance", 16.0, sigma=0.05),
        RewardTerm("bottom", 128.0, sigma=0.005),
        *PENALTY_TERMS,
    )
)


@register_env("PegInHoleAssembly-v1", max_episode_steps=200)
class PegInHoleAssemblyEnv(SpaceManipulationEnv):
    """
    **Task Description:**
    Pick up a peg lying in front of a hole module and insert it into the hole. On the Moon, Mars and Earth the
    arm rides the rover and the module stands on the ground; in orbit the arm and the module sit on a station's
    work platform and nothing falls: the peg floats where it was placed. 10 s episodes: 200 control steps at
    20 Hz, physics at 100 Hz.

    **Randomizations:**
    - the peg and hole pair (during reconfiguration, one per parallel env): `asset_source="dataset"` gives the
      20 x 20 mm square profile peg, 100 or 200 mm long (drawn per env), and its 22 x 22 mm, 20 mm deep socket
      on a 50 x 50 mm post; `asset_source="procedural"` gives a peg with a random profile (circle or 3-12 sided
      polygon, squashed), size and taper, and a module with the matching hole cut at a random offset, tilt
      (up to 20 deg) and depth, `clearance` (default 1 mm) wider than the peg
    - the peg lies on a random stable side 0.24-0.28 m in front of the module, y within +-5 cm, its tip
      toward the arm within +-11 deg
    - the terrain (or nothing, in orbit) and the sun direction (during reconfiguration); the arm's initial joints

    **Success Conditions:**
    - an insertable end of the peg is inside the hole at least 90% of its depth: its tip within 10% of the
      depth from the hole's bottom along the hole's axis, and within the peg's radius of that axis
    - the peg's axis is aligned with the hole's axis within 5 deg

    **Reward:** dense terms (`REWARD_TABLE`, reported in `info["reward_terms"]`) of the reference: reach
    1/0.25, grasp 4, lift 8 (0.05-0.55 m, falloff 0.05), axis alignment 8 (1 - cos of the angle, /0.5), twist
    alignment 4/0.2 using the profile's rotational symmetry, tip to entrance 16/0.05, tip to bottom 128/0.005;
    all measured with the hole's own entrance and bottom frames (the reference measured a fixed entrance, even
    for tilted holes) and the peg end nearest the entrance. Penalties as in every task; success gives the
    maximum (169); `normalized_dense` maps [-1.5, 169] onto [0, 1].
    """

    SUPPORTED_DOMAINS = ("moon", "mars", "orbit", "earth")
    DEFAULT_DOMAIN = "moon"
    EPISODE_SECONDS = 10.0
    REWARD_TABLE = REWARD_TABLE

    def __init__(self, *args, clearance: Optional[float] = None, asset_source: Optional[str] = None, **kwargs):
        self.clearance = socket_clearance(clearance, asset_source or self.DEFAULT_ASSET_SOURCE)
        super().__init__(*args, asset_source=asset_source, **kwargs)

    def _make_mount(self):
        return make_station() if self.domain.ground_texture is None else make_rover()

    def _load_scene(self, options: dict):
        self._load_domain_scene()
        seeds = self._asset_seeds()
        if self.asset_source == "procedural":
            pairs = [make_peg_hole_pair(seed, self.clearance) for seed in seeds]
            pegs, holes = [p for p, _ in pairs], [h for _, h in pairs]
        else:
            lengths = np.where(np.asarray(seeds) % 2 == 0, "short", "long")
            pegs = [load_dataset_object(f"profile_peg_{length}") for length in lengths]
            holes = [load_dataset_object("profile_socket")] * self.num_envs
        self.hole_module = build_actor_per_env(self.scene, holes, "hole_module", body_type="static", initial_pose=sapien.Pose(p=MODULE_POSITION))
        self.hole_assets = holes
        self.peg = build_samples(self, pegs, "peg")
        self._store_task_geometry(pegs, holes)

    def _store_task_geometry(self, pegs, holes):
        """Per-env tensors of the pairs' frames and facts, for batched evaluation and rewards."""
        device = self.device
        module = np.eye(4)
        module[:3, 3] = MODULE_POSITION
        as_tensor = lambda x: torch.as_tensor(np.asarray(x), dtype=torch.float32, device=device)  # noqa: E731
        self._entrance = as_tensor([module @ h.frames["entrance"] for h in holes])
        self._bottom = as_tensor([module @ h.frames["bottom"] for h in holes])
        self._depth = as_tensor([h.info["depth"] for h in holes])
        self._symmetry = torch.as_tensor([p.info["symmetry_order"] for p in pegs], device=device)
        self._peg_radius = as_tensor([p.info["radius"] for p in pegs])
        self._peg_height = as_tensor([p.info["height"] for p in pegs])
        self._peg_ends = as_tensor([[p.frames["end_0"], p.frames.get("end_1", p.frames["end_0"])] for p in pegs])
        self._peg_end_valid = torch.as_tensor([[True, "end_1" in p.frames] for p in pegs], device=device)
        # lying on a side: never on an end
        self._placement = RestingPlacement(pegs, device, exclude_axis=np.array([0.0, 0.0, 1.0]))

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        with torch.device(self.device):
            b = len(env_idx)
            rng = self._batched_episode_rng[env_idx]
            self._initialize_agent(env_idx)
            resting = self._placement.face_down(env_idx, rng.uniform(0.0, 1.0))
            # turn about z so the lying peg's axis (tip to head) points along the drawn heading, away from the arm
            axis = quaternion_to_matrix(resting)[:, :, 2]
            heading = torch.as_tensor(rng.uniform(-PEG_HEADING_JITTER, PEG_HEADING_JITTER), dtype=torch.float32)
            quat = turned_about_z(resting, heading - torch.atan2(axis[:, 1], axis[:, 0]))
            position = torch.zeros((b, 3))
            position[:, 0] = MODULE_POSITION[0] - torch.as_tensor(rng.uniform(*PEG_DISTANCE), dtype=torch.float32)
            position[:, 1] = torch.as_tensor(rng.uniform(-PEG_LATERAL, PEG_LATERAL), dtype=torch.float32)
            position[:, 2] = self._placement.height_on_ground(env_idx, quat, PEG_DROP_CLEARANCE)
            self.peg.set_pose(Pose.create_from_pq(position, quat))
            self._peg_start_height[env_idx] = position[:, 2]

    def _after_reconfigure(self, options: dict):
        super()._after_reconfigure(options)
        self._peg_start_height = torch.zeros(self.num_envs, device=self.device)

    def peg_end_frames(self) -> torch.Tensor:
        """World poses (n, 2, 4, 4) of the peg's insertable ends (the second repeats the first if only one)."""
        pose = self.peg.pose
        return pose_matrix(pose.p, pose.q).unsqueeze(1) @ self._peg_ends

    def evaluate(self):
        state = insertion_measures(self.peg_end_frames(), self._peg_end_valid, self._entrance, self._bottom, self._depth, self._symmetry)
        is_inserted = (state["inserted_fraction"] >= INSERTED_FRACTION) & (state["lateral_offset"] <= self._peg_radius)
        is_aligned = state["axis_angle"] <= ALIGNMENT_TOLERANCE
        return dict(
            success=is_inserted & is_aligned,
            is_inserted=is_inserted,
            is_aligned=is_aligned,
            is_grasped=self.is_grasping(self.peg),
            **state,
        )

    def _get_obs_extra(self, info: dict):
        tcp_position, tcp_rotation = self.tcp_frame()
        obs = self._shared_obs_extra(tcp_position, tcp_rotation)
        obs["is_grasped"] = info["is_grasped"].float().unsqueeze(-1)
        if self.obs_mode_struct.use_state:
            peg = self.peg.pose
            position, rotation = relative_pose(tcp_position, tcp_rotation, peg.p, rotation_matrix(peg.q))
            end = _select(self.peg_end_frames(), info["peg_end"])
            end_position, end_rotation = end[:, :3, 3], end[:, :3, :3]
            entrance, _ = relative_pose(end_position, end_rotation, self._entrance[:, :3, 3], self._entrance[:, :3, :3])
            bottom, hole_rotation = relative_pose(end_position, end_rotation, self._bottom[:, :3, 3], self._bottom[:, :3, :3])
            obs.update(
                peg_pos_in_tcp=position,
                peg_rot6d_in_tcp=rotation_6d(rotation),
                entrance_in_peg_end=entrance,
                bottom_in_peg_end=bottom,
                hole_rot6d_in_peg_end=rotation_6d(hole_rotation),
                hole_depth=self._depth.unsqueeze(-1),
                symmetry_order=self._symmetry.float().unsqueeze(-1),
            )
        return obs

    def _reward_inputs(self, info: dict) -> dict[str, torch.Tensor]:
        peg = self.peg.pose.p
        return dict(
            reach=torch.linalg.norm(self.agent.tcp.pose.p - peg, dim=-1),
            grasp=info["is_grasped"],
            lift=band_distance(peg[:, 2] - self._peg_start_height, *LIFT_BAND),
            align_axis=1.0 - torch.cos(info["axis_angle"]),
            align_twist=info["twist_error"],
            entrance=info["tip_to_entrance"],
            bottom=info["tip_to_bottom"],
        )

    def compute_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        return REWARD_TABLE.dense(info["reward_terms"], info["success"])

    def compute_normalized_dense_reward(self, obs: Any, action: torch.Tensor, info: dict):
        return REWARD_TABLE.normalize(self.compute_dense_reward(obs, action, info))


def _select(values: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``values[i, index[i]]`` for every env i."""
    return values[torch.arange(len(index), device=index.device), index]
