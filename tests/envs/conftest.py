import gymnasium as gym
import pytest

import mani_skill_space  # noqa: F401  (registers the envs)


@pytest.fixture(scope="module")
def make_sample_collection():
    """Makes SampleCollection-v1 envs (state observations, no rendering) with the given kwargs; closes them all when
    the module's tests are done."""
    envs = []

    def _make(**kwargs):
        env = gym.make("SampleCollection-v1", obs_mode="state", render_backend="none", **kwargs)
        envs.append(env)
        return env

    yield _make
    for env in envs:
        env.close()
