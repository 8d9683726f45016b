"""Procgen-style levels: a scene rebuild's procedural content is a function of its level alone."""

import hashlib
import subprocess
import sys

import numpy as np
import pytest
import sapien
from mani_skill.envs.utils.randomization.batched_rng import BatchedRNG

import mani_skill_space  # noqa: F401
from mani_skill_space.kwarg_checks import KwargError
from mani_skill_space.levels import LevelRange, check_level_kwargs

DIGEST_SCRIPT = """
import sys, gymnasium as gym, mani_skill_space
sys.path.insert(0, {tests!r})
from test_levels import scene_digest
env = gym.make("SampleCollection-v1", obs_mode="state", render_backend="none", num_levels=1, start_level={level})
env.reset(seed=123)
print(scene_digest(env))
"""


def _collision_bytes(actor) -> bytes:
    body = actor._objs[0]
    component = body.find_component_by_type(sapien.physx.PhysxRigidBaseComponent)
    return b"".join(np.round(shape.get_vertices(), 6).tobytes() for shape in component.collision_shapes)


def scene_digest(env) -> str:
    """The procedural content of env 0's scene: the sample's and the terrain's collision geometry and the sun."""
    unwrapped = env.unwrapped
    parts = [_collision_bytes(unwrapped.sample), _collision_bytes(unwrapped.ground), np.round(unwrapped._sun_directions[0], 9).tobytes()]
    return hashlib.sha1(b"".join(parts)).hexdigest()


@pytest.fixture(scope="module")
def make(make_sample_collection):
    return make_sample_collection


def test_one_level_gives_the_same_scene_for_any_episode_seed_and_its_own_episode_randomness(make):
    env = make(num_levels=1, start_level=7)
    digests, sample_positions = set(), set()
    for seed in (0, 1, 2, 999):
        env.reset(seed=seed)
        assert env.unwrapped.levels.tolist() == [7]
        digests.add(scene_digest(env))
        sample_positions.add(tuple(np.round(env.unwrapped.sample.pose.p[0].numpy(), 5)))
    assert len(digests) == 1
    assert len(sample_positions) == 4  # the object's placement still follows the episode seed


def test_disjoint_level_ranges_give_disjoint_scenes(make):
    def digests(start_level):
        env = make(num_levels=3, start_level=start_level)
        seen = {}
        for seed in range(8):
            env.reset(seed=seed)
            seen[int(env.unwrapped.levels[0])] = scene_digest(env)
            assert LevelRange(3, start_level).level_of(seed) == int(env.unwrapped.levels[0])
        return seen

    low, high = digests(0), digests(1000)
    assert set(low) <= {0, 1, 2} and set(high) <= {1000, 1001, 1002}
    assert len(low) > 1 and len(high) > 1  # several levels drawn
    assert not set(low.values()) & set(high.values())


def test_unbounded_levels_are_the_episode_seeds_and_build_what_that_level_builds(make):
    unbounded = make()
    unbounded.reset(seed=41)
    assert unbounded.unwrapped.levels.tolist() == [41]
    pinned = make(num_levels=1, start_level=41)
    pinned.reset(seed=5)
    assert scene_digest(unbounded) == scene_digest(pinned)
    shifted = make(start_level=1000)
    shifted.reset(seed=41)
    assert shifted.unwrapped.levels.tolist() == [1041]


def test_a_level_gives_the_same_bytes_in_a_fresh_process(make):
    env = make(num_levels=1, start_level=3)
    env.reset(seed=123)
    script = DIGEST_SCRIPT.format(tests=str(__import__("pathlib").Path(__file__).parent), level=3)
    fresh = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout.split()[-1]
    assert fresh == scene_digest(env)


def test_batched_draws_give_each_sub_scene_its_own_level():
    seeds = np.arange(8) * 17 + 3
    levels = LevelRange(num_levels=5, start_level=100).draw(seeds, BatchedRNG.from_seeds(seeds))
    again = LevelRange(num_levels=5, start_level=100).draw(seeds, BatchedRNG.from_seeds(seeds))
    assert levels.shape == (8,) and levels.tolist() == again.tolist()
    assert ((levels >= 100) & (levels < 105)).all() and len(set(levels.tolist())) > 1
    assert LevelRange(0, 10).draw(seeds, BatchedRNG.from_seeds(seeds)).tolist() == (seeds + 10).tolist()
    assert LevelRange(5, 100).contains(104) and not LevelRange(5, 100).contains(105) and LevelRange(0, 100).contains(10**6)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(num_levels=-1), "num_levels must be an integer >= 0"),
        (dict(num_levels=2.5), "num_levels must be an integer >= 0"),
        (dict(start_level=True), "start_level must be an integer >= 0"),
        (dict(start_level=2**31), "start_level must be an integer >= 0 and <= 2147483647"),
        (dict(start_level=2**31 - 1, num_levels=2**31 + 2), "start_level + num_levels must be <= 4294967296"),
    ],
)
def test_bad_level_kwargs_name_the_valid_range(kwargs, message):
    with pytest.raises(KwargError, match=message.replace("+", r"\+")):
        check_level_kwargs(kwargs)
