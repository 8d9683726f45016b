
import functools

import numpy as np
import sapien
import torch
from mani_skill.utils.registration import register_env
from mani_skill.utils.structs.pose import Pose

from mani_skill_space.dataset import load_dataset_object
from mani_skill_space.envs.arm_reach import ArmPlanning
from mani_skill_space.envs.base import PENALTY_TERMS, SocketClearance, SpaceManipulationEnv
from mani_skill_space.envs.building import build_actor_per_env
from mani_skill_space.envs.insertion import (
    INSERTION_VALUE,
    PEG_DROP_CLEARANCE,
    PEG_HEADING_JITTER,
    PegInsertion,
    allow_insertable_faces,
    insertion_inputs,
    insertion_terms,
    lying_peg_orientation,
    peg_placement,
    pegs_latched_in_holes,
    seated_pairs,
)
from mani_skill_space.envs.peg_in_hole_assembly import PEG_DISTANCE, module_position, reachable_peg_hole_pair
from mani_skill_space.geometry import relative_pose, rotation_6d, rotation_matrix
from mani_skill_space.procgen.asset import Asset, CollisionPart
from mani_skill_space.procgen.mounts import make_rover, make_station
from mani_skill_space.procgen.peg_hole import module_block
from mani_skill_space.rewards import RewardTable, RewardTerm

PAIR_COUNT = 4
MODULE_YS = (0.255, 0.085, -0.085, -0.255)
"""The four hole modules (0.15 m blocks, 2 cm apart) stand in a row across the arm's front at Peg-in-Hole's
distance (``peg_in_hole_assembly.module_position``: 0.6 m for procedural modules, 0.7 m for the dataset posts): the
grid is one row, so that every module is as far from the arm as Peg-in-Hole's and each peg lies in front of its
own module, as in Peg-in-Hole."""
PEG_LANE_YS = (0.18, 0.06, -0.06, -0.18)
"""Each peg lies in its own lane in front of the modules, in the modules' order but closer together (0.12 m apart)
than the modules, within Peg-in-Hole's lateral range and a little beyond: at the outer modules' 0.255 m the arm
missed its grasps."""
PEG_LATERAL = 0.02
"""Each peg lies within this (m) of its lane's centre line (Peg-in-Hole: 0.05)."""

PEG_TERMS = insertion_terms(prefix="peg_")
"""Peg-in-Hole's terms, for the peg nearest to going in."""
REWARD_TABLE = RewardTable((RewardTerm("pegs_inserted", PAIR_COUNT * INSERTION_VALUE), *PEG_TERMS, *PENALTY_TERMS))


def module_positions(asset_source: str) -> np.ndarray:
    """(4, 3) world positions of the hole modules' base centres for ``asset_source``."""
    x, _, z = module_position(asset_source)
    return np.array([[x, y, z] for y in MODULE_YS])


def pair_arm_planning(mount: Asset, urdf_path: str, positions: np.ndarray, index: int) -> ArmPlanning:
    """The arm's own check of the pair at module ``index`` (``envs.arm_reach``): its peg lying in its lane, in the
    middle of the range in front of the modules, with the other modules' blocks as obstacles besides the mount. A
    hand holding a peg over a tilted hole reaches sideways over the module beside it (modules 2 cm apart, the hand
    20 cm wide): traced on seed 62008, the oracle found no push into the outer hole that missed the next module's top."""
    x = float(positions[index][0]) - float(np.mean(PEG_DISTANCE))
    spread = ((PEG_DISTANCE[1] - PEG_DISTANCE[0]) / 2, PEG_LATERAL, PEG_HEADING_JITTER)
    return ArmPlanning(mount, urdf_path, (x, PEG_LANE_YS[index]), _module_block_points(tuple(map(tuple, positions)), index), spread)


@functools.lru_cache(maxsize=8)
def _module_block_points(positions: tuple, index: int) -> np.ndarray:
    """Obstacle points (world) on the blocks of every module but ``index`` (every block is the same box; the holes
    cut into them do not matter here)."""
    from mani_skill_space.oracles.base import surface_points

    block = Asset(name="module_block", visual_parts=(), collision_parts=(CollisionPart(module_block()),))
    points = []
    for i, position in enumerate(positions):
        if i != index:
            pose = np.eye(4)
            pose[:3, 3] = position
            points.append(surface_points(block, pose))
    return np.concatenate(points)


@register_env("MultiPegInHoleAssembly-v1", max_episode_steps=800)
class MultiPegInHoleAssemblyEnv(SocketClearance, SpaceManipulationEnv):
    """
    **Task Description:**
    Peg-in-Hole with four pairs: four pegs lie in front of a row of four hole modules, one in front of each; put
    every peg into a hole. On the Moon, Mars and Earth the arm rides the rover and the modules stand on the ground;
    in orbit the arm and the modules sit on a station's work platform and nothing falls. 40 s episodes (10 s per
    peg): 800 control steps at 20 Hz, physics at 100 Hz.

    **Randomizations:**
    - the four peg and hole pairs (during reconfiguration, each from its own asset seed, one set per parallel
      env): `asset_source="dataset"` gives the 20 x 20 mm square profile peg, 100 or 200 mm long (drawn per peg),
      and the 22 x 22 mm socket on a 50 x 50 mm post; `asset_source="procedural"` gives Peg-in-Hole's procedural
      pairs (random profile, size, taper; hole at a random offset, tilt up to 20 deg and depth, `clearance`
      default 1 mm), each drawn again until the arm can insert it at its module (`reachable_peg_hole_pair`, with
      the arm's own planning, `pair_arm_planning`: the push into the hole must miss the modules, and the grasp must
      be reachable wherever the episode may lay the peg)
    - the modules stand at x = 0.6 m (procedural; the dataset posts at 0.7 m, as in Peg-in-Hole), y = +-0.085 and
      +-0.255 m; each peg lies on a random stable side 0.24-0.28 m in front of its module, within +-2 cm of its
      centre line, its tip toward the arm within +-11 deg (for procedural pairs, only on a side from which the arm
      can take it and hold it over its hole, from which the fingers can hold it, `envs.insertion.face_checks_of`,
      and from which the arm's own planning pushes it to its hole's bottom without touching a module,
      `envs.arm_reach`; each peg's `info["insertable_faces"]`)
    - the terrain (or nothing, in orbit) and the sun direction (during reconfiguration); the arm's initial joints

    **Success Conditions:**
    - every hole holds a peg inserted as in Peg-in-Hole (an insertable end at least 90% of the depth in, on the
      hole's axis within the peg's radius, axes aligned within 5 deg). A peg counts in any hole it fits: the
      dataset's pegs fit every socket; a procedural peg fits only its own hole (the four pairs are distinct shapes)

    **Latches:** each hole holds a peg inserted in it (Peg-in-Hole's latch, `envs.insertion.latch_force`), so
    that in orbit a released peg stays in; nothing that is not inserted is captured.

    **Reward:** staged, so that progress is monotone: 169 per filled hole (`pegs_inserted`), plus Peg-in-Hole's
    dense terms (reach 1, grasp 4, lift 8, axis 8, twist 4, entrance 16, bottom 128; at most 169 together) for
    the peg not yet in whose terms add up to the most, measured in its own hole (or, if another peg filled that
    one, the first empty hole it fits), and the shared penalties. Success gives the table's maximum (845);
    `info["stage"]` is the number of filled holes (4 = success). `normalized_dense` maps [-1.5, 845] onto [0, 1].
    """

    SUPPORTED_DOMAINS = ("moon", "mars", "orbit", "earth")
    DEFAULT_DOMAIN = "moon"
    EPISODE_SECONDS = 10.0 * PAIR_COUNT
    REWARD_TABLE = REWARD_TABLE

    def _make_mount(self):
        return make_rover(cargo_bin=False) if self.domain.has_ground else make_station()

    def _load_scene(self, options: dict):
        self._load_domain_scene()
        arm_base = self.mount.frames["arm_mount"][:3, 3]
        positions = module_positions(self.asset_source)
        pegs, holes = [], []  # [pair][env]
        for i, position in enumerate(positions):
            seeds = self._asset_seeds()
            if self.asset_source == "procedural":
                arm = pair_arm_planning(self.mount, self.agent.urdf_path, positions, i)
                pairs = [reachable_peg_hole_pair(seed, self.clearance, arm_base, position, arm) for seed in seeds]
                pegs.append([peg for peg, _ in pairs])
                holes.append([hole for _, hole in pairs])
            else:
                pegs.append([load_dataset_object(f"profile_peg_{'short' if seed % 2 == 0 else 'long'}") for seed in seeds])
                holes.append([load_dataset_object("profile_socket")] * self.num_envs)
        self.hole_modules = [
            build_actor_per_env(self.scene, holes[i], f"hole_module_{i}", body_type="static", initial_pose=sapien.Pose(p=positions[i]))
            for i in range(PAIR_COUNT)
        ]
        self.hole_assets = holes
        self.module_positions = positions
        # awake however slowly they drift: a peg let go in orbit must drift out unless its hole's latch holds it
        self.pegs = [self.build_graspable(pegs[i], f"peg_{i}", never_sleep=True) for i in range(PAIR_COUNT)]
        self.peg_assets = pegs
        self._store_task_geometry(pegs, holes, positions)

    def _store_task_geometry(self, pegs, holes, positions):
        device = self.device
        modules = []
        for position in positions:
            module = np.eye(4)
            module[:3, 3] = position
            modules.append(module)
        pairs, envs = range(PAIR_COUNT), range(self.num_envs)
        self.insertion = PegInsertion.from_assets(
            pegs=[[pegs[i][e] for i in pairs] for e in envs],
            hole_entrances=[[modules[i] @ holes[i][e].frames["entrance"] for i in pairs] for e in envs],
            hole_bottoms=[[modules[i] @ holes[i][e].frames["bottom"] for i in pairs] for e in envs],
            hole_depths=[[holes[i][e].info["depth"] for i in pairs] for e in envs],
            symmetry_orders=[[pegs[i][e].info["symmetry_order"] for i in pairs] for e in envs],
            device=device,
        )
        self._peg_placements = [peg_placement(pegs[i], device) for i in pairs]
        if self.asset_source == "procedural":
            for i, placement in enumerate(self._peg_placements):
                allow_insertable_faces(placement, pegs[i])
        # (peg, hole) pairs that fit: every socket takes every dataset peg; a procedural peg only its own hole
        same_shapes = self.asset_source == "dataset"
        self._fits = torch.ones((PAIR_COUNT, PAIR_COUNT), dtype=torch.bool, device=device) if same_shapes else torch.eye(PAIR_COUNT, dtype=torch.bool, device=device)

    def _after_reconfigure(self, options: dict):
        super()._after_reconfigure(options)
        self._peg_start_height = torch.zeros((self.num_envs, PAIR_COUNT), device=self.device)
        self._peg_masses = [peg.mass.to(self.device) for peg in self.pegs]

    def _initialize_episode(self, env_idx: torch.Tensor, options: dict):
        with torch.device(self.device):
            b = len(env_idx)
            rng = self._batched_episode_rng[env_idx]
            self._initialize_agent(env_idx)
            for i, (peg, placement) in enumerate(zip(self.pegs, self._peg_placements)):
                quat = lying_peg_orientation(placement, env_idx, rng)
                position = torch.zeros((b, 3))
                position[:, 0] = float(self.module_positions[i, 0]) - torch.as_tensor(rng.uniform(*PEG_DISTANCE), dtype=torch.float32)
                position[:, 1] = PEG_LANE_YS[i] + torch.as_tensor(rng.uniform(-PEG_LATERAL, PEG_LATERAL), dtype=torch.float32)
                position[:, 2] = placement.height_on_ground(env_idx, quat, PEG_DROP_CLEARANCE)
                peg.set_pose(Pose.create_from_pq(position, quat))
                self._peg_start_height[env_idx, i] = position[:, 2]

    def _latch_forces(self):
        """Each hole latches a peg inserted in it (see the card)."""
        in_hole = seated_pairs(self.insertion, self.insertion.all_pair_measures(self.peg_end_frames()), self._fits)
        return pegs_latched_in_holes(self.pegs, self._peg_masses, in_hole, self.insertion.hole_bottom)

    # ------------------------------------------------------------------ measures
    def peg_end_frames(self) -> torch.Tensor:
        """World poses (n, 4 pegs, 2 ends, 4, 4) of the pegs' insertable ends (the second repeats the first if only one)."""
        positions = torch.stack([peg.pose.p for peg in self.pegs], dim=1)
        quaternions = torch.stack([peg.pose.q for peg in self.pegs], dim=1)
        return self.insertion.end_frames(positions, quaternions)

    def evaluate(self):
        measures = self.insertion.all_pair_measures(self.peg_end_frames())
        in_hole = seated_pairs(self.insertion, measures, self._fits)
        hole_filled = in_hole.any(dim=1)
        holes_filled = hole_filled.sum(dim=1)
        grasped = torch.stack([self.is_grasping(peg) for peg in self.pegs], dim=1)
        return dict(
            success=holes_filled == PAIR_COUNT,
            stage=holes_filled,
            hole_filled=hole_filled,
            peg_inserted=in_hole.any(dim=2),
            holes_filled=holes_filled,
            grasped=grasped,
            is_grasped=grasped.any(dim=1),
            **{f"pair_{k}": v for k, v in measures.items()},
        )

    def target_holes(self, info: dict) -> torch.Tensor:
        """(n, 4) the hole each peg should go to: its own if still empty, else the first empty hole it fits (its own
        if there is none)."""
        own = torch.arange(PAIR_COUNT, device=self.device).expand(self.num_envs, PAIR_COUNT)
        open_fitting = ~info["hole_filled"][:, None, :] & self._fits[None]  # (n, pegs, holes)
        first_open = torch.where(open_fitting.any(dim=2), open_fitting.int().argmax(dim=2), own)
        return torch.where(info["hole_filled"], first_open, own)

    # ------------------------------------------------------------------ observations
    def _get_obs_extra(self, info: dict):
        tcp_position, tcp_rotation = self.tcp_frame()
        obs = self._shared_obs_extra(tcp_position, tcp_rotation)
        obs["grasped"] = info["grasped"].float()
        obs["hole_filled"] = info["hole_filled"].float()
        if self.obs_mode_struct.use_state:
            n = self.num_envs
            pegs = torch.stack([peg.pose.raw_pose for peg in self.pegs], dim=1)
            peg_position, peg_rotation = relative_pose(tcp_position[:, None], tcp_rotation[:, None], pegs[..., :3], rotation_matrix(pegs[..., 3:]))
            entrance = self.insertion.hole_entrance
            entrance_position, entrance_rotation = relative_pose(tcp_position[:, None], tcp_rotation[:, None], entrance[..., :3, 3], entrance[..., :3, :3])
            obs.update(
                pegs_pos_in_tcp=peg_position.reshape(n, -1),
                pegs_rot6d_in_tcp=rotation_6d(peg_rotation).reshape(n, -1),
                holes_pos_in_tcp=entrance_position.reshape(n, -1),
                holes_rot6d_in_tcp=rotation_6d(entrance_rotation).reshape(n, -1),
                peg_inserted=info["peg_inserted"].float(),
                hole_depth=self.insertion.hole_depth,
                symmetry_order=self.insertion.symmetry_order.float(),
            )
        return obs

    # ------------------------------------------------------------------ reward
    def _reward_inputs(self, info: dict) -> dict[str, torch.Tensor]:
        """``pegs_inserted`` and Peg-in-Hole's term inputs for the peg not yet in whose terms add up to the most (at
        rest once every hole is filled)."""
        n = self.num_envs
        rows = torch.arange(n, device=self.device)[:, None]
        target = self.target_holes(info)
        pair = lambda key: info[f"pair_{key}"][rows, torch.arange(PAIR_COUNT, device=self.device)[None], target]  # noqa: E731
        positions = torch.stack([peg.pose.p for peg in self.pegs], dim=1)
        measures = {key: pair(key) for key in ("axis_angle", "twist_error", "tip_to_entrance", "tip_to_bottom")}
        inputs = insertion_inputs(self.agent.tcp.pose.p[:, None], positions, info["grasped"].float(), self._peg_start_height, measures)
        inputs = {f"peg_{name}": value for name, value in inputs.items()}
        progress = sum(term(inputs[term.name]) for term in PEG_TERMS).masked_fill(info["peg_inserted"], -1.0)
        best = progress.argmax(dim=1)
        chosen = {name: value[rows[:, 0], best] for name, value in inputs.items()}
        all_filled = info["holes_filled"] == PAIR_COUNT
        off = {"peg_grasp": torch.zeros(n, device=self.device)}
        chosen = {name: torch.where(all_filled, off.get(name, torch.full_like(value, float("inf"))), value) for name, value in chosen.items()}
        return dict(pegs_inserted=info["holes_filled"].float() / PAIR_COUNT, **chosen)
