import pytest

from mani_skill_space.metrics import EpisodeResult, summarize, wilson_interval


@pytest.mark.parametrize(
    "successes, trials, expected",
    [
        (0, 10, (0.0, 0.2775)),
        (1, 10, (0.0179, 0.4042)),
        (5, 10, (0.2366, 0.7634)),
        (10, 10, (0.7225, 1.0)),
        (90, 100, (0.8256, 0.9448)),
        (197, 200, (0.9568, 0.9949)),
    ],
)
def test_wilson_interval_matches_known_values(successes, trials, expected):
    low, high = wilson_interval(successes, trials)
    assert low == pytest.approx(expected[0], abs=1e-4)
    assert high == pytest.approx(expected[1], abs=1e-4)


def test_wilson_interval_rejects_impossible_counts():
    with pytest.raises(ValueError):
        wilson_interval(3, 2)
    with pytest.raises(ValueError):
        wilson_interval(0, 0)


def test_summary_rates_means_and_intervals():
    results = [EpisodeResult(s, s % 2 == 0, s % 4 == 0, float(s), 100 + s) for s in range(8)]
    summary = summarize(results)
    assert summary["episodes"] == 8
    assert summary["success_once"] == 0.5 and summary["success_at_end"] == 0.25
    assert summary["success_once_ci95"] == wilson_interval(4, 8)
    assert summary["return_mean"] == 3.5 and summary["episode_len_mean"] == 103.5


def test_mean_stage_needs_every_episode_staged():
    staged = [EpisodeResult(s, False, False, 0.0, 100, stage=s % 3) for s in range(6)]
    assert summarize(staged)["stage_mean"] == 1.0
    assert summarize(staged[:2] + [EpisodeResult(9, True, True, 1.0, 50)])["stage_mean"] is None
    assert summarize([EpisodeResult(0, True, True, 1.0, 50)])["stage_mean"] is None
