
from typing import Optional

import numpy as np
import sapien
import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.pose import Pose

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.envs.arm_reach import ArmPlanning, face_checks_with_the_arm, module_obstacles
from mani_skill_space.envs.base import PENALTY_TERMS, SocketClearance, SpaceManipulationEnv
from mani_skill_space.envs.building import build_actor_per_env
from mani_skill_space.envs.insertion import (
    PEG_DROP_CLEARANCE,
    PegInsertion,
    insertion_inputs,
    insertion_terms,
    is_aligned,
    is_inserted,
    face_checks_of,
    feasibility_record,
    hole_in_peg_end,
    insertable_faces,
    latch_force,
    lying_peg_orientation,
    peg_placement,
    redrawn_seed,
)
from mani_skill_space.geometry import relative_pose, rotation_6d, rotation_matrix
from mani_skill_space.procgen.asset import Asset
from mani_skill_space.procgen.mounts import make_rover, make_station
from mani_skill_space.procgen.peg_hole import build_hole_module, peg_and_hole_layout
from mani_skill_space.rewards import RewardTable

MODULE_POSITION = (0.7, 0.0, 0.0)
"""The dataset socket's post stands here, on the ground or the station's platform: far enough from the rover that
even the 200 mm peg, lying in front of the module, clears the rover's front."""
PROCEDURAL_MODULE_POSITION = (0.6, 0.0, 0.0)
"""The procedural hole module stands 10 cm nearer the arm: its hole may be tilted up to 28 degrees in any direction
(up to 20 about each level axis, as in the reference), and over a hole at 0.7 m tilted away from the arm the hand
holding a peg on the hole's axis is at the edge of the Panda's reach, where a few millimetres of slip in the grasp
leave no arm configuration (measured with the oracle on procedural pairs, seeds 60000-60059 in every domain: 69%
inserted at 0.7 m, 83% at 0.6 m, 68% at 0.55 m, where the arm reaches for pegs close under it). The 200 mm dataset
peg needs the dataset post's 0.7 m (at 0.6 m the oracle inserted 25 of 37)."""


def module_position(asset_source: str) -> tuple[float, float, float]:
    """Where the hole module (or the dataset socket's post) stands for ``asset_source``."""
    return PROCEDURAL_MODULE_POSITION if asset_source == "procedural" else MODULE_POSITION
PEG_DISTANCE = (0.24, 0.28)
"""The peg lies this far in front of the module (toward the arm), as in the reference."""
PEG_LATERAL = 0.05

MAX_PAIR_DRAWS = 50
"""Draws of a procedural pair per asset seed before giving up on finding one the arm can insert (about one in
six draws is rejected: see ``reachable_peg_hole_pair``)."""

REWARD_TABLE = RewardTable((*insertion_terms(), *PENALTY_TERMS))


def reachable_peg_hole_pair(
    seed: int, clearance: float, arm_base: np.ndarray, module_position=PROCEDURAL_MODULE_POSITION, arm: Optional[ArmPlanning] = None
) -> tuple[Asset, Asset]:
    """The procedural pair of ``seed``, drawn again (from seeds derived from it, deterministically) while no
    resting face of its peg passes the solvability checks (``envs.insertion.face_checks_of``: reachable for
    insertion by an arm at ``arm_base`` with the module at ``module_position``, and tall enough to grip; given
    ``arm``, also the arm's own planning, ``envs.arm_reach.face_checks_with_the_arm``, with the module itself as an
    obstacle as the oracles see it while pushing, ``module_obstacles``). The hole's
    ``info["feasibility"]`` records the checks (``feasibility_record``): how many draws it took and how many faces
    pass each (the episode's peg lies on one that passes all); given ``arm``, the peg's ``info["insertable_faces"]``
    lists those faces."""
    module = np.eye(4)
    module[:3, 3] = module_position
    for draw in range(MAX_PAIR_DRAWS):
        peg, layout = peg_and_hole_layout(redrawn_seed(seed, draw), clearance)
        bottom = module @ layout.bottom
        if arm is None:
            checks = face_checks_of(peg, bottom, arm_base)
            hole = build_hole_module(layout) if bool(checks["insertable"].any()) else None  # cut only what is kept
        else:
            hole = build_hole_module(layout)
            obstacles = module_obstacles(hole, module, float(peg.info["radius"]))
            if arm.extra_obstacles is not None:
                obstacles = np.concatenate([arm.extra_obstacles, obstacles])
            checks = face_checks_with_the_arm(peg, bottom, hole.info["depth"], arm.rest_xy, arm.mount, arm.urdf_path, obstacles, arm.rest_spread)
        if bool(checks["insertable"].any()):
            hole.info["feasibility"] = feasibility_record(draw + 1, [checks])
            if arm is not None:
                peg.info["insertable_faces"] = checks["insertable"].tolist()
            return peg, hole
    raise RuntimeError(f"no procedural peg/hole pair the arm can insert in {MAX_PAIR_DRAWS} draws from seed {seed}")


@register_env("PegInHoleAssembly-v1", max_episode_steps=200)
class PegInHoleAssemblyEnv(SocketClearance, SpaceManipulationEnv):
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
      (up to 20 deg about each level axis) and depth, `clearance` (default 1 mm, at most 7 mm) wider than the peg
    - the module stands 0.7 m in front of the arm (the dataset post) or 0.6 m (the procedural block, whose tilted
      holes need the reach); the peg lies on a random stable side 0.24-0.28 m in front of the module, y within
      +-5 cm, its tip toward the arm within +-11 deg; for procedural pairs, only on a side that passes the
      solvability checks (`envs.insertion.face_checks_of`): the arm can take it there and hold it over the hole,
      and it lies at least 1 cm tall and not widest only at its base, so the fingers can hold it; a pair with no
      such side is drawn again, and
      the module asset's `info["feasibility"]` records the checks
    - the terrain (or nothing, in orbit) and the sun direction (during reconfiguration); the arm's initial joints

    **Success Conditions:**
    - an insertable end of the peg is inside the hole at least 90% of its depth: its tip within 10% of the
      depth from the hole's bottom along the hole's axis, and within the peg's radius of that axis
    - the peg's axis is aligned with the hole's axis within 5 deg

    **Latch:** the hole holds a peg that meets both conditions: it pulls the peg toward its bottom as hard as
    1 g would, damping its motion (`envs.insertion.latch_force`), so that in orbit a released peg stays in.
    It never captures a peg that is not inserted.

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
    SUPPORTS_FREE_FLYER = True

    def _make_mount(self):
        return make_rover() if self.domain.has_ground else make_station()

    def _load_scene(self, options: dict):
        self._load_domain_scene()
        self.module_position = module_position(self.asset_source)
        seeds = self._asset_seeds()
        if self.asset_source == "procedural":
            arm_base = self.mount.frames["arm_mount"][:3, 3]
            pairs = [reachable_peg_hole_pair(seed, self.clearance, arm_base) for seed in seeds]
            pegs, holes = [p for p, _ in pairs], [h for _, h in pairs]
        else:
            lengths = np.where(np.asarray(seeds) % 2 == 0, "short", "long")
            pegs = [load_dataset_object(f"profile_peg_{length}") for length in lengths]
            holes = [load_dataset_object("profile_socket")] * self.num_envs
        self.hole_module = build_actor_per_env(self.scene, holes, "hole_module", body_type="static", initial_pose=sapien.Pose(p=self.module_position))
        self.hole_assets = holes
        # awake however slowly it drifts: a peg let go in orbit must drift out unless the socket's latch holds it
        self.peg = self.build_graspable(pegs, "peg", never_sleep=True)
        self.peg_assets = pegs
        module = np.eye(4)
        module[:3, 3] = self.module_position
        self.insertion = PegInsertion.from_assets(
            pegs=[[p] for p in pegs],
            hole_entrances=[[module @ h.frames["entrance"]] for h in holes],
            hole_bottoms=[[module @ h.frames["bottom"]] for h in holes],
            hole_depths=[[h.info["depth"]] for h in holes],
            symmetry_orders=[[p.info["symmetry_order"]] for p in pegs],
            device=self.device,
        )
        self._placement = peg_placement(pegs, self.device)
        if self.asset_source == "procedural":
            arm_base = torch.as_tensor(self.mount.frames["arm_mount"][:3, 3], dtype=torch.float32, device=self.device)
            tips = self.insertion.peg_ends[:, 0, 0]
            self._placement.allow_only(insertable_faces(self._placement, tips, self.insertion.hole_bottom[:, 0], self.insertion.symmetry_order[:, 0], arm_base))

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        with torch.device(self.device):
            b = len(env_idx)
            rng = self._batched_episode_rng[env_idx]
            self._initialize_agent(env_idx)
            quat = lying_peg_orientation(self._placement, env_idx, rng)
            position = torch.zeros((b, 3))
            position[:, 0] = self.module_position[0] - torch.as_tensor(rng.uniform(*PEG_DISTANCE), dtype=torch.float32)
            position[:, 1] = torch.as_tensor(rng.uniform(-PEG_LATERAL, PEG_LATERAL), dtype=torch.float32)
            position[:, 2] = self._placement.height_on_ground(env_idx, quat, PEG_DROP_CLEARANCE)
            self.peg.set_pose(Pose.create_from_pq(position, quat))
            self._peg_start_height[env_idx] = position[:, 2]

    def _after_reconfigure(self, options: dict):
        super()._after_reconfigure(options)
        self._peg_start_height = torch.zeros(self.num_envs, device=self.device)
        self._peg_mass = self.peg.mass.to(self.device)

    def _latch_forces(self):
        measures = self.insertion.measures(self.peg_end_frames())
        seated = (is_inserted(measures, self.insertion.peg_radius) & is_aligned(measures))[:, 0]
        into_hole = -self.insertion.hole_bottom[:, 0, :3, 2]
        return [(self.peg, latch_force(seated, into_hole, self.peg.linear_velocity, self._peg_mass))]

    def peg_end_frames(self) -> torch.Tensor:
        """World poses (n, 1, 2, 4, 4) of the peg's insertable ends (the second repeats the first if only one):
        ``PegInsertion``'s layout, with one peg."""
        pose = self.peg.pose
        return self.insertion.end_frames(pose.p[:, None], pose.q[:, None])

    def evaluate(self):
        measures = self.insertion.measures(self.peg_end_frames())
        inserted, aligned = is_inserted(measures, self.insertion.peg_radius)[:, 0], is_aligned(measures)[:, 0]
        return dict(
            success=inserted & aligned,
            is_inserted=inserted,
            is_aligned=aligned,
            is_grasped=self.is_grasping(self.peg),
            **{name: value[:, 0] for name, value in measures.items()},
        )

    def _get_obs_extra(self, info: dict):
        tcp_position, tcp_rotation = self.tcp_frame()
        obs = self._shared_obs_extra(tcp_position, tcp_rotation)
        obs["is_grasped"] = info["is_grasped"].float().unsqueeze(-1)
        if self.obs_mode_struct.use_state:
            peg = self.peg.pose
            position, rotation = relative_pose(tcp_position, tcp_rotation, peg.p, rotation_matrix(peg.q))
            end = _select(self.peg_end_frames()[:, 0], info["peg_end"])
            entrance, bottom, hole_rotation = hole_in_peg_end(end, self.insertion.hole_entrance[:, 0], self.insertion.hole_bottom[:, 0])
            obs.update(
                peg_pos_in_tcp=position,
                peg_rot6d_in_tcp=rotation_6d(rotation),
                entrance_in_peg_end=entrance,
                bottom_in_peg_end=bottom,
                hole_rot6d_in_peg_end=rotation_6d(hole_rotation),
                hole_depth=self.insertion.hole_depth,
                symmetry_order=self.insertion.symmetry_order.float(),
            )
        return obs

    def _reward_inputs(self, info: dict) -> dict[str, torch.Tensor]:
        return insertion_inputs(self.agent.tcp.pose.p, self.peg.pose.p, info["is_grasped"], self._peg_start_height, info)


def _select(values: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``values[i, index[i]]`` for every env i."""
    return values[torch.arange(len(index), device=index.device), index]
