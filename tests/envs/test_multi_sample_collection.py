"""MultiSampleCollection-v1: three samples in their own lanes, success when all are in the bin, a staged reward."""

import gymnasium as gym
import numpy as np
import pytest
import sapien
import torch
from mani_skill.utils.structs.pose import Pose

import mani_skill_space  # noqa: F401
from mani_skill_space.envs.multi_sample_collection import REWARD_TABLE, SAMPLE_COUNT, SAMPLE_VALUE


@pytest.fixture(scope="module", params=["procedural", "dataset"])
def env(request):
    env = gym.make("MultiSampleCollection-v1", asset_source=request.param, obs_mode="state", render_backend="none")
    yield env
    env.close()


def _hull_bytes(actor) -> bytes:
    component = actor._objs[0].find_component_by_type(sapien.physx.PhysxRigidDynamicComponent)
    return b"".join(np.round(shape.get_vertices(), 6).tobytes() for shape in component.collision_shapes)


def test_three_samples_lie_apart_in_their_lanes(env):
    for seed in range(5):
        env.reset(seed=seed)
        positions = env.unwrapped.sample_positions()[0]
        assert positions.shape == (SAMPLE_COUNT, 3)
        gaps = torch.cdist(positions[:, :2], positions[:, :2]) + torch.eye(SAMPLE_COUNT)
        assert gaps.min() > 0.1
        assert (positions[:, 1].argsort(descending=True) == torch.arange(SAMPLE_COUNT)).all()
    hulls = {_hull_bytes(sample) for sample in env.unwrapped.samples}
    assert len(hulls) == (SAMPLE_COUNT if env.unwrapped.asset_source == "procedural" else 1)


def test_the_stage_counts_samples_in_the_bin_and_the_reward_rises_with_it(env):
    env.reset(seed=3)
    unwrapped = env.unwrapped
    rewards, stages = [], []
    hold = torch.zeros(env.action_space.shape)
    hold[..., -1] = 1.0  # open hand, arm still
    for collected in range(SAMPLE_COUNT + 1):
        if collected:
            sample = unwrapped.samples[collected - 1]
            spot = unwrapped.bin_target[0] + torch.tensor([0.0, 0.09 * (collected - 2), 0.0])
            sample.set_pose(Pose.create_from_pq(spot[None], torch.tensor([[1.0, 0.0, 0.0, 0.0]])))
        for _ in range(15):  # let it settle
            _, reward, _, _, info = env.step(hold)
        rewards.append(float(env.unwrapped.compute_dense_reward(None, hold, info)[0]))
        stages.append(int(info["stage"][0]))
    assert stages == [0, 1, 2, 3]
    assert bool(info["success"][0]) and rewards[-1] == REWARD_TABLE.max_reward == SAMPLE_COUNT * SAMPLE_VALUE + SAMPLE_VALUE
    assert all(later > earlier for earlier, later in zip(rewards, rewards[1:])), rewards
    assert set(info["reward_terms"]) == set(REWARD_TABLE.names)
