"""The shipped checkpoints: the manifest describes each one truly, each loads and runs in the evaluation CLI, and
they stay small."""

import importlib.util
import json
import sys
import textwrap
from pathlib import Path

import pytest

from mani_skill_space.learning import BehaviourCloningPolicy, save_checkpoint
from mani_skill_space.learning.manifest import ManifestError, load_manifest

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT / "baselines" / "checkpoints" / "manifest.toml"
SIZE_LIMIT = 30 * 2**20


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"baseline_{name}", ROOT / "baselines" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_the_shipped_manifest_matches_its_checkpoints_and_they_stay_small():
    entries = load_manifest(MANIFEST)
    assert entries
    folder = MANIFEST.parent
    assert sum(p.stat().st_size for p in folder.iterdir()) < SIZE_LIMIT
    assert {p.resolve() for p in folder.glob("*.pt")} == {entry.path for entry in entries}  # nothing unlisted


def test_every_shipped_checkpoint_loads_and_runs_in_the_evaluation_cli(tmp_path):
    score = _script("score_checkpoints")
    rows = score.main(score.Args(output=tmp_path / "checkpoints", episodes=2, num_workers=2))
    assert [row["name"] for row in rows] == [entry.name for entry in load_manifest(MANIFEST)]
    assert all(row["summary"]["episodes"] == 2 for row in rows)
    assert (tmp_path / "checkpoints.md").read_text().count("\n| ") == len(rows)  # the rows after the header


def test_only_scores_the_named_entries_and_keeps_the_other_rows(manifest, tmp_path):
    score = _script("score_checkpoints")
    path = manifest(ENTRY + ENTRY.replace('name = "tiny"', 'name = "other"'))
    output = tmp_path / "scores"
    earlier = dict(name="other", env_id="SampleCollection-v1", kwargs={}, command="", manifest_success_at_end=0.5, seeds=[20000])
    earlier["summary"] = dict(episodes=1, success_once=1.0, success_once_ci95=[0.2, 1.0], success_at_end=1.0, success_at_end_ci95=[0.2, 1.0], return_mean=9.0, stage_mean=None)
    with pytest.raises(ValueError, match=r"has no rows for \['other'\], which --only leaves out"):
        score.main(score.Args(manifest=path, output=output, episodes=1, num_workers=1, only=("tiny",)))
    output.with_suffix(".json").write_text(json.dumps([earlier]))
    with pytest.raises(ValueError, match=r"--only names \['tini'\].*valid choices: tiny, other"):
        score.main(score.Args(manifest=path, output=output, episodes=1, num_workers=1, only=("tini",)))
    rows = score.main(score.Args(manifest=path, output=output, episodes=1, num_workers=1, only=("tiny",)))
    assert [row["name"] for row in rows] == ["tiny", "other"]
    assert rows[0]["summary"]["episodes"] == 1 and rows[1] == earlier
    assert json.loads(output.with_suffix(".json").read_text()) == json.loads(json.dumps(rows))


def test_the_checkpoint_table_has_a_stage_column_only_where_an_env_is_staged():
    table = _script("score_checkpoints").markdown_table

    def row(name, stage_mean):
        summary = dict(episodes=2, success_once=0.0, success_once_ci95=[0.0, 0.2], success_at_end=0.0, success_at_end_ci95=[0.0, 0.2], return_mean=1.0, stage_mean=stage_mean)
        return dict(name=name, env_id="E", kwargs={}, manifest_success_at_end=0.0, summary=summary, seeds=[5000, 5001])

    assert "stage" not in table([row("plain", None)])
    lines = table([row("plain", None), row("staged", 1.5)]).splitlines()
    assert lines[0].endswith("| stage | manifest |")
    assert lines[2].endswith("| - | 0% |") and lines[3].endswith("| 1.50 | 0% |")


ENTRY = """
[[checkpoints]]
name = "tiny"
path = "tiny.pt"
env_id = "SampleCollection-v1"
kwargs = { domain = "mars", asset_source = "dataset" }
obs_mode = "state"
control_mode = "pd_ee_delta_pose"
command = "python baselines/bc.py --demos tubes.h5"
success_at_end = 0.5
episodes = 100
seed_start = 20000
"""


@pytest.fixture
def manifest(tmp_path):
    kwargs = dict(state_dim=49, action_dim=7, hidden=8, depth=1)
    save_checkpoint(tmp_path / "tiny.pt", "bc", BehaviourCloningPolicy(**kwargs), kwargs, "SampleCollection-v1", {"domain": "mars", "asset_source": "dataset", "sensor_configs": {}}, "state", "pd_ee_delta_pose")

    def write(text):
        path = tmp_path / "manifest.toml"
        path.write_text(textwrap.dedent(text))
        return path

    return write


def test_a_true_entry_loads(manifest):
    (entry,) = load_manifest(manifest(ENTRY))
    assert entry.name == "tiny" and entry.path.name == "tiny.pt" and entry.policy.startswith("checkpoint:")


@pytest.mark.parametrize(
    "change, message",
    [
        (('asset_source = "dataset"', 'asset_source = "procedural"'), "kwargs is .* but tiny.pt records"),
        (('control_mode = "pd_ee_delta_pose"', 'control_mode = "pd_joint_pos"'), "control_mode is 'pd_joint_pos' but tiny.pt records 'pd_ee_delta_pose'"),
        (("success_at_end = 0.5", "success_at_end = 50"), r"success_at_end must be a rate in \[0, 1\]"),
        (("episodes = 100", "episodes = 0"), "episodes must be an integer >= 1"),
        (('path = "tiny.pt"', 'path = "missing.pt"'), "No checkpoint at"),
        (("seed_start = 20000", "seed_start = 20000\nscore = 1"), r"unknown keys \['score'\]"),
        (('command = "python baselines/bc.py --demos tubes.h5"', ""), r"missing keys \['command'\]"),
    ],
)
def test_a_wrong_entry_is_named(manifest, change, message):
    with pytest.raises((ManifestError, ValueError), match=message):
        load_manifest(manifest(ENTRY.replace(*change)))
