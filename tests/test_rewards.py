import math

import pytest
import torch

from mani_skill_space.rewards import RewardTable, RewardTerm, action_rate, band_distance, tolerance

NUM_ENVS = 8
TABLE = RewardTable((RewardTerm("reach", 1.0, sigma=0.25), RewardTerm("grasp", 4.0), RewardTerm("lift", 8.0, sigma=0.1), RewardTerm("penalty", -1.5)))


def test_tolerance_is_one_at_zero_and_decays_like_tanh():
    d = torch.tensor([0.0, 0.25, 1e6])
    torch.testing.assert_close(tolerance(d, 0.25), torch.tensor([1.0, 1 - math.tanh(1.0), 0.0]))


def test_band_distance_is_zero_inside_and_grows_outside():
    value = torch.tensor([0.0, 0.25, 0.5, 0.75, 1.0])
    torch.testing.assert_close(band_distance(value, 0.25, 0.75), torch.tensor([0.25, 0.0, 0.0, 0.0, 0.25]))


def test_action_rate_is_normalised_by_the_action_range():
    low, high = -torch.ones(7), torch.ones(7)
    assert action_rate(torch.ones(NUM_ENVS, 7), -torch.ones(NUM_ENVS, 7), low, high).tolist() == [1.0] * NUM_ENVS
    assert action_rate(torch.zeros(NUM_ENVS, 7), torch.zeros(NUM_ENVS, 7), low, high).tolist() == [0.0] * NUM_ENVS


def _batch():
    torch.manual_seed(0)
    return dict(
        reach=torch.rand(NUM_ENVS) * 0.5,
        grasp=(torch.rand(NUM_ENVS) > 0.5).float(),
        lift=torch.rand(NUM_ENVS) * 0.3,
        penalty=torch.rand(NUM_ENVS),
    )


def test_weighted_terms_are_computed_per_env():
    inputs = _batch()
    weighted = TABLE.weighted(inputs)
    for i in range(NUM_ENVS):
        assert weighted["reach"][i] == pytest.approx(1 - math.tanh(inputs["reach"][i].item() / 0.25), rel=1e-6)
        assert weighted["grasp"][i] == 4.0 * inputs["grasp"][i]
        assert weighted["penalty"][i] == pytest.approx(-1.5 * inputs["penalty"][i].item(), rel=1e-6)


def test_dense_reward_sums_terms_and_success_gives_the_maximum():
    weighted = TABLE.weighted(_batch())
    success = torch.tensor([True, False] * (NUM_ENVS // 2))
    dense = TABLE.dense(weighted, success)
    expected = sum(weighted.values())
    torch.testing.assert_close(dense[~success], expected[~success])
    assert TABLE.max_reward == 13.0
    assert torch.all(dense[success] == 13.0)


def test_normalised_reward_maps_the_reward_bounds_onto_zero_and_one():
    assert TABLE.min_reward == -1.5
    torch.testing.assert_close(TABLE.normalize(torch.tensor([-1.5, 13.0])), torch.tensor([0.0, 1.0]))
    worst = TABLE.weighted(dict(reach=torch.full((NUM_ENVS,), 1e6), grasp=torch.zeros(NUM_ENVS), lift=torch.full((NUM_ENVS,), 1e6), penalty=torch.ones(NUM_ENVS)))
    normalised = TABLE.normalize(TABLE.dense(worst, torch.zeros(NUM_ENVS, dtype=torch.bool)))
    assert torch.all(normalised >= 0) and torch.all(normalised <= 1)
    for _ in range(20):
        batch = TABLE.normalize(TABLE.dense(TABLE.weighted(_batch()), torch.rand(NUM_ENVS) > 0.8))
        assert torch.all((0 <= batch) & (batch <= 1))


def test_inputs_must_name_exactly_the_terms():
    with pytest.raises(KeyError, match="penalty"):
        TABLE.weighted(dict(reach=torch.zeros(1), grasp=torch.zeros(1), lift=torch.zeros(1)))
