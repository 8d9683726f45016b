"""The batched GPU path of every task: 16 parallel envs on ManiSkill's GPU simulation (``physx_cuda``), in every
domain and asset source of each task. Needs CUDA (``conftest.py`` marks these tests ``gpu`` and skips them
without it); run them with ``pytest -m gpu tests/gpu``.

One env per configuration is built and shared by the tests of ``TestBatchedEnv`` (a module-scoped parametrised
fixture: pytest runs every test of a configuration before building the next one). Each test starts from a seeded
reset of its own, so their order does not matter. The CPU counterparts of these checks (one env) are in
``tests/envs/test_every_task.py``, ``test_state_contract.py`` and ``test_levels.py``.
"""

from __future__ import annotations

import gc
from dataclasses import dataclass
from typing import Any, Iterator

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch
from mani_skill.vector.wrappers.gymnasium import ManiSkillVectorEnv

import mani_skill_space
from mani_skill_space.envs import task_class

NUM_ENVS = 16
CONFIGURATIONS = [
    (env_id, domain, source)
    for env_id in mani_skill_space.ENV_IDS
    for domain in task_class(env_id).SUPPORTED_DOMAINS
    for source in task_class(env_id).SUPPORTED_ASSET_SOURCES
]
"""Every (env id, domain, asset source) the package supports."""

SINGLE_MODEL_DATASET = {
    "SampleCollection-v1": "the dataset source has one model (the sample tube), the same in every sub-scene",
    "MultiSampleCollection-v1": "the dataset source has one model (the sample tube), the same in every sub-scene",
    "SolarPanelAssembly-v1": "the dataset source is one set (two long, two short profile pegs and one panel), the same in every sub-scene",
}
"""Tasks whose dataset source puts the same objects in every sub-scene: nothing to compare between sub-scenes. The
other tasks' dataset sources pick per env (Debris Capture: a model by seed; Peg-in-Hole: a short or long peg)."""

ZERO_ACTION_STEPS = 50
STATE_ATOL = 1e-4
"""Poses and velocities written to and read back from the GPU buffers may differ in the last bits (ManiSkill's own
GPU tests compare with 1e-4)."""


@dataclass
class Batched:
    env: gym.Env
    env_id: str
    domain: str
    asset_source: str

    @property
    def base(self):
        return self.env.unwrapped


def configuration_id(configuration: tuple[str, str, str]) -> str:
    return "-".join(configuration)


def make_env(env_id: str, domain: str, asset_source: str) -> gym.Env:
    """16 envs on the GPU simulation, state observations, no renderer (nothing here reads a camera)."""
    return gym.make(
        env_id,
        num_envs=NUM_ENVS,
        sim_backend="physx_cuda",
        render_backend="none",
        domain=domain,
        asset_source=asset_source,
        obs_mode="state",
    )


def close_env(env: gym.Env) -> None:
    """Close and let go of a GPU env (ManiSkill frees the GPU memory of a PhysX system when it is collected)."""
    env.close()
    del env
    gc.collect()
    torch.cuda.empty_cache()


@pytest.fixture(scope="module", params=CONFIGURATIONS, ids=configuration_id)
def batched(request) -> Iterator[Batched]:
    env = make_env(*request.param)
    yield Batched(env, *request.param)
    close_env(env)


# ---------------------------------------------------------------------------------------------------- helpers
def free_objects(base) -> dict[str, Any]:
    """The task's free (dynamic, per-env) objects: those its ``build_graspable`` built, by name, as the merged
    ``Actor`` views ManiSkill keeps in ``scene.actor_views`` (one body per sub-scene)."""
    return {name: base.scene.actor_views[name] for name in sorted(base._graspable_radius)}


def sub_scene_geometry(actor, index: int) -> bytes:
    """The collision geometry of ``actor``'s body in its ``index``-th sub-scene: every shape's kind, local pose and
    (mesh shapes) vertices."""
    body = actor._objs[index].find_component_by_type(sapien.physx.PhysxRigidBaseComponent)
    parts = []
    for shape in body.get_collision_shapes():
        parts.append(type(shape).__name__.encode())
        pose = shape.get_local_pose()
        parts.append(np.round(np.concatenate([pose.p, pose.q]), 6).tobytes())
        if hasattr(shape, "get_vertices"):
            parts.append(np.round(np.asarray(shape.get_vertices(), dtype=np.float64), 6).tobytes())
    return b"".join(parts)


def sub_scene_digests(base) -> list[bytes]:
    """Per sub-scene, the collision geometry of all of the task's free objects there."""
    objects = free_objects(base).values()
    return [b"".join(sub_scene_geometry(actor, i) for actor in objects) for i in range(base.num_envs)]


def tensor_leaves(tree: Any, path: tuple = ()) -> Iterator[tuple[str, torch.Tensor]]:
    """(path, tensor) for every tensor in nested dicts, lists and tuples."""
    if isinstance(tree, torch.Tensor):
        yield "/".join(map(str, path)), tree
    elif isinstance(tree, dict):
        for key, value in tree.items():
            yield from tensor_leaves(value, (*path, key))
    elif isinstance(tree, (list, tuple)):
        for i, value in enumerate(tree):
            yield from tensor_leaves(value, (*path, i))


def cloned(state: dict) -> dict:
    return {key: cloned(value) if isinstance(value, dict) else value.clone() for key, value in state.items()}


def assert_leading_dim(tree: Any, what: str, size: int = NUM_ENVS) -> None:
    leaves = list(tensor_leaves(tree))
    assert leaves, f"{what}: no tensors"
    wrong = {path: tuple(t.shape) for path, t in leaves if t.ndim == 0 or t.shape[0] != size}
    assert not wrong, f"{what}: tensors whose leading dim is not {size}: {wrong}"


def seeded_random_actions(env: gym.Env, seed: int):
    env.action_space.seed(seed)
    return lambda: env.action_space.sample()


# ---------------------------------------------------------------------------------------------------- tests
class TestBatchedEnv:
    def test_each_sub_scene_has_its_own_objects_and_they_differ(self, batched: Batched):
        """Per-env heterogeneous assets: each free object is one body per sub-scene (merged with ``Actor.merge``),
        and the collision geometry differs between sub-scenes."""
        base = batched.base
        objects = free_objects(base)
        assert objects, "the task built no free objects with build_graspable"
        for name, actor in objects.items():
            assert actor.merged and len(actor._objs) == NUM_ENVS, name
            assert actor._scene_idxs.tolist() == list(range(NUM_ENVS)), f"{name}: body i must be in sub-scene i"
            assert actor.px_body_type == "dynamic", name
        if batched.asset_source == "dataset" and batched.env_id in SINGLE_MODEL_DATASET:
            pytest.skip(SINGLE_MODEL_DATASET[batched.env_id])
        digests = sub_scene_digests(base)
        assert len(set(digests)) > 1, f"every one of the {NUM_ENVS} sub-scenes has the same objects ({', '.join(objects)})"

    def test_partial_reset_changes_only_the_reset_envs(self, batched: Batched):
        env, base = batched.env, batched.base
        env.reset(seed=0)
        sample = seeded_random_actions(env, 0)
        for _ in range(3):
            env.step(sample())
        before = cloned(base.get_state_dict())
        poses_before = {name: actor.pose.raw_pose.clone() for name, actor in free_objects(base).items()}

        env_idx = torch.tensor([0, 3])
        env.reset(options={"env_idx": env_idx})

        after = cloned(base.get_state_dict())
        reset = torch.zeros(NUM_ENVS, dtype=torch.bool, device=base.device)
        reset[env_idx.to(base.device)] = True
        for name, actor in free_objects(base).items():
            moved = torch.linalg.norm(actor.pose.p - poses_before[name][:, :3], dim=-1) > 1e-4
            assert moved[reset].all(), f"{name}: a reset env's object kept its pose: {moved.tolist()}"
        assert base.elapsed_steps[reset].tolist() == [0, 0]
        assert (base.elapsed_steps[~reset] == 3).all(), base.elapsed_steps.tolist()
        leaves_before = dict(tensor_leaves(before))
        leaves_after = dict(tensor_leaves(after))
        assert leaves_before.keys() == leaves_after.keys()
        for path, value in leaves_before.items():
            if path.startswith("controller/"):
                # ManiSkill 3.0.1 resets the controllers after restoring the reset mask to all envs (BaseEnv.reset):
                # a target-tracking controller's targets are upstream's business; pd_ee_delta_pose keeps none
                continue
            untouched = torch.allclose(value[~reset], leaves_after[path][~reset], atol=STATE_ATOL, rtol=0)
            assert untouched, f"{path}: a partial reset of envs 0 and 3 changed the state of another env"

    def test_batched_shapes(self, batched: Batched):
        env, base = batched.env, batched.base
        obs, info = env.reset(seed=1)
        assert obs.shape == (NUM_ENVS, *base.single_observation_space.shape), obs.shape
        assert obs.device.type == "cuda"
        assert_leading_dim(obs, "reset obs")
        obs, reward, terminated, truncated, info = env.step(seeded_random_actions(env, 1)())
        assert obs.shape == (NUM_ENVS, *base.single_observation_space.shape), obs.shape
        assert torch.isfinite(obs).all()
        assert reward.shape == (NUM_ENVS,) and torch.isfinite(reward).all()
        assert terminated.shape == (NUM_ENVS,) and truncated.shape == (NUM_ENVS,)
        assert info["success"].shape == (NUM_ENVS,)
        assert set(info["reward_terms"]) == set(task_class(batched.env_id).REWARD_TABLE.names)
        assert_leading_dim(info, "step info")
        assert_leading_dim(base.evaluate(), "evaluate()")

    def test_no_object_leaves_its_sub_scene(self, batched: Batched):
        """Sub-scenes share one physics world, ``sim_config.spacing`` apart: an object that moved half the spacing
        would be in (or could touch) a neighbour's. Positions the API returns are local to each sub-scene. In orbit
        (zero gravity) nothing holds the objects down; in the other domains this also catches one falling through
        the ground. Zero actions for 50 steps."""
        env, base = batched.env, batched.base
        env.reset(seed=2)
        half_spacing = base.sim_config.spacing / 2
        objects = free_objects(base)
        start = {name: actor.pose.p.clone() for name, actor in objects.items()}
        zero = torch.zeros((NUM_ENVS, *base.single_action_space.shape), device=base.device)
        for step in range(ZERO_ACTION_STEPS):
            env.step(zero)
            for name, actor in objects.items():
                position = actor.pose.p
                assert torch.isfinite(position).all(), f"{name}: non-finite position at step {step}"
                outside = position[:, :2].abs().amax(dim=-1) >= half_spacing
                assert not outside.any(), f"{name}: outside its sub-scene's cell at step {step} in envs {outside.nonzero().flatten().tolist()}"
        for name, actor in objects.items():
            distance = torch.linalg.norm(actor.pose.p - start[name], dim=-1)
            assert (distance < half_spacing).all(), f"{name}: moved {distance.max().item():.2f} m in {ZERO_ACTION_STEPS} steps (spacing {2 * half_spacing} m)"

    def test_state_dict_round_trip(self, batched: Batched):
        env, base = batched.env, batched.base
        env.reset(seed=3)
        sample = seeded_random_actions(env, 3)
        for _ in range(2):
            env.step(sample())
        state = cloned(base.get_state_dict())
        for _ in range(5):
            env.step(sample())
        stepped = dict(tensor_leaves(base.get_state_dict()))
        assert not torch.equal(stepped["task/elapsed_steps"], state["task"]["elapsed_steps"])
        base.set_state_dict(state)
        restored = dict(tensor_leaves(base.get_state_dict()))
        expected = dict(tensor_leaves(state))
        assert restored.keys() == expected.keys()
        for path, value in expected.items():
            assert restored[path].shape == value.shape and restored[path].shape[0] == NUM_ENVS, path
            assert torch.allclose(restored[path], value, atol=STATE_ATOL, rtol=1e-5), f"{path}: not restored"

    def test_same_seed_same_initial_obs_in_fresh_envs(self, batched: Batched):
        observations, digests = [], []
        for _ in range(2):
            fresh = make_env(batched.env_id, batched.domain, batched.asset_source)
            try:
                obs, _ = fresh.reset(seed=7)
                observations.append(obs.clone().cpu())
                digests.append(sub_scene_digests(fresh.unwrapped))
            finally:
                close_env(fresh)
        torch.testing.assert_close(observations[0], observations[1], rtol=0, atol=1e-6)
        assert digests[0] == digests[1], "two fresh envs built different objects"
        other, _ = batched.env.reset(seed=8)
        assert not torch.allclose(other.cpu(), observations[0], atol=1e-4), "another seed gave the same initial obs"

    def test_vector_env_runs_an_episode_and_records_metrics(self, batched: Batched):
        """ManiSkill's ``ManiSkillVectorEnv`` (as its RL baselines use it) to the time limit; its final info carries
        the episode metrics of every env. The wrapper is not closed: it would close the shared env."""
        env, base = batched.env, batched.base
        limit = gym.spec(batched.env_id).max_episode_steps  # the registered time limit (the gym.make'd env's spec has none)
        assert limit == task_class(batched.env_id).nominal_episode_steps()
        vector_env = ManiSkillVectorEnv(env, NUM_ENVS, ignore_terminations=True, record_metrics=True)
        vector_env.reset(seed=4)
        vector_env.action_space.seed(4)
        for step in range(1, limit + 1):
            _, reward, terminated, truncated, info = vector_env.step(vector_env.action_space.sample())
            assert reward.shape == (NUM_ENVS,) and not terminated.any()
            assert info["episode"]["return"].shape == (NUM_ENVS,)
            if truncated.any():
                break
        assert step == limit and truncated.all(), f"episode ended at step {step} of {limit}: {truncated.tolist()}"
        final = info["final_info"]["episode"]
        for key in ("success_once", "success_at_end", "return"):
            assert final[key].shape == (NUM_ENVS,), key
        assert torch.isfinite(final["return"]).all()
        assert (final["episode_len"] == limit).all()
        assert (base.elapsed_steps == 0).all(), "the wrapper resets every env at the end of the episode"
