import json
import textwrap
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from mani_skill_space import eval as evaluation
from mani_skill_space.metrics import EpisodeResult, summarize
from mani_skill_space.policies import load_policy
from mani_skill_space.rollout import run_episode

SUITE = """
name = "tiny"
episodes = 2
seed_start = 5

[[configurations]]
env_id = "SampleCollection-v1"
kwargs = { domain = "mars", asset_source = "dataset" }
"""


@pytest.fixture
def suite(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(textwrap.dedent(SUITE))
    return path


def _run(suite, output, policies, **kwargs):
    return evaluation.main(evaluation.Args(suite=suite, policy=policies, output_dir=output, num_workers=2, **kwargs))


def test_cli_writes_a_well_formed_table_and_json(suite, tmp_path, capsys):
    report = _run(suite, tmp_path / "out", ("random", "zero"))
    table = (tmp_path / "out" / "results.md").read_text().strip().splitlines()
    rows = [line for line in table if line.startswith("| ") and not line.startswith("| configuration")]
    assert len(rows) == 2  # 1 configuration x 2 policies
    assert all(line.count("|") == 8 for line in table if line.startswith("|"))
    assert "% [" in rows[0]
    saved = json.loads((tmp_path / "out" / "results.json").read_text())
    assert saved == json.loads(json.dumps(report))
    first = saved["rows"][0]
    assert first["summary"]["episodes"] == 2 and [e["seed"] for e in first["episodes"]] == [5, 6]
    assert first["summary"]["success_once"] == 0.0  # random actions do not solve the task
    assert "| SampleCollection-v1/mars/dataset | random |" in capsys.readouterr().out


def test_same_suite_and_seeds_give_the_same_numbers(suite, tmp_path):
    first = _run(suite, tmp_path / "a", ("random",))
    second = _run(suite, tmp_path / "b", ("random",))
    assert first == second


def test_oracle_solves_the_suite_and_videos_are_saved(suite, tmp_path):
    report = _run(suite, tmp_path / "out", ("oracle",), video=1)
    summary = report["rows"][0]["summary"]
    assert summary["success_once"] == 1.0 and summary["success_at_end"] == 1.0
    assert summary["episode_len_mean"] < 150
    videos = list((tmp_path / "out" / "videos").rglob("*.mp4"))
    assert [v.name for v in videos] == ["oracle_seed5.mp4"]


def test_user_policy_hook(suite, tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(Path(__file__).parent))
    report = _run(suite, tmp_path / "out", ("policies_for_tests:make_policy",), episodes=1)
    assert report["rows"][0]["summary"]["episodes"] == 1


def test_bad_policy_specs_are_rejected():
    with pytest.raises(ValueError, match="random, zero, oracle"):
        load_policy("dreamer")
    with pytest.raises(ModuleNotFoundError):
        load_policy("no_such_module:make")


class _StagedEnv(gym.Env):
    """Four steps whose info reports stages 1, 2, 1, 1: the episode's highest stage is 2."""

    observation_space = gym.spaces.Box(-1, 1, (1,))
    action_space = gym.spaces.Box(-1, 1, (1,))
    max_episode_steps = 4
    stages = (1, 2, 1, 1)

    def reset(self, seed=None, options=None):
        self.t = 0
        return np.zeros(1, np.float32), {}

    def step(self, action):
        stage = self.stages[self.t]
        self.t += 1
        info = {"success": torch.tensor([False]), "stage": torch.tensor([stage])}
        return np.zeros(1, np.float32), 0.0, False, self.t == self.max_episode_steps, info


def test_episodes_record_the_highest_stage_reached():
    result = run_episode(_StagedEnv(), load_policy("zero"), seed=0)
    assert result.stage == 2


def test_table_has_a_stage_column_only_for_staged_tasks():
    def row(stage_mean):
        summary = summarize([EpisodeResult(0, True, True, 1.0, 10, stage=stage_mean)])
        return {"configuration": "c", "policy": "p", "summary": summary}

    plain = evaluation.markdown_table({"suite": "s", "rows": [row(None)]})
    assert "stage" not in plain
    staged = evaluation.markdown_table({"suite": "s", "rows": [row(None), row(3)]}).splitlines()
    assert staged[2].endswith("| stage |")
    assert staged[-2].endswith("| - |") and staged[-1].endswith("| 3.00 |")


def test_each_evaluation_worker_takes_its_share_of_the_cores(monkeypatch):
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    monkeypatch.setattr(evaluation.os, "cpu_count", lambda: 8)
    assert [evaluation.worker_torch_threads(n) for n in (1, 2, 3, 8, 16)] == [8, 4, 2, 1, 1]
    with ProcessPoolExecutor(1, mp_context=get_context("spawn"), initializer=evaluation.limit_torch_threads, initargs=(1,)) as pool:
        assert pool.submit(torch.get_num_threads).result() == 1
