import json
import textwrap

import pytest

from mani_skill_space import eval as evaluation
from mani_skill_space.cli_support import UserError
from mani_skill_space.learning import BehaviourCloningPolicy, save_checkpoint
from mani_skill_space.protocol import (
    IN_DISTRIBUTION,
    load_protocol,
    markdown_matrix,
    matrix_row,
    newcombe_interval,
    protocol_suite,
    shipped_protocols,
)
from mani_skill_space.suites import SuiteError

PROTOCOL = """
name = "tiny"
episodes = 1
seed_start = 30

[train]
env_id = "SampleCollection-v1"
kwargs = { domain = "mars", asset_source = "procedural", num_levels = 2 }

[[tests]]
name = "held-out levels"
kwargs = { num_levels = 0, start_level = 1000000 }

[[tests]]
name = "heavier"
kwargs = { object_mass_scale = 2.0 }
"""


def _write(tmp_path, text):
    path = tmp_path / "protocol.toml"
    path.write_text(textwrap.dedent(text))
    return path


def test_every_shipped_protocol_loads_with_checked_cells():
    names = shipped_protocols()
    assert {"levels", "asset_source", "domains", "factors", "peg_in_hole", "debris_capture"} <= set(names)
    for name in names:
        protocol = load_protocol(name)
        assert protocol.tests and protocol.episodes >= 50


def test_cells_merge_each_test_onto_the_training_condition(tmp_path):
    protocol = load_protocol(_write(tmp_path, PROTOCOL))
    suite = protocol_suite(protocol, "SampleCollection-v1", {"domain": "moon", "asset_source": "procedural", "num_levels": 5})
    cells = {c.name: c.kwargs for c in suite.configurations}
    assert list(cells) == [IN_DISTRIBUTION, "held-out levels", "heavier"]
    assert cells[IN_DISTRIBUTION] == {"domain": "moon", "asset_source": "procedural", "num_levels": 5}
    assert cells["held-out levels"] == {"domain": "moon", "asset_source": "procedural", "num_levels": 0, "start_level": 1000000}
    assert cells["heavier"]["object_mass_scale"] == 2.0 and cells["heavier"]["num_levels"] == 5
    assert all(c.seeds == [30] for c in suite.configurations)


@pytest.mark.parametrize(
    "change, message",
    [
        (("[[tests]]\nname = \"heavier\"", "[[tests]]\nname = \"held-out levels\""), "unique name"),
        (("object_mass_scale = 2.0", "object_mass_scale = 20.0"), "cell 'heavier': object_mass_scale must be a finite number"),
        (("object_mass_scale = 2.0", "object_scale = 1.1, color = 1"), "cell 'heavier': SampleCollectionEnv takes no kwarg 'color'"),
        (("seed_start = 30", "seed_start = 30\nsplit = 1"), "unknown protocol key 'split'"),
        (('env_id = "SampleCollection-v1"', 'env_id = "Nope-v1"'), "unknown env id 'Nope-v1'"),
    ],
)
def test_protocol_mistakes_are_named(tmp_path, change, message):
    with pytest.raises(SuiteError, match=message):
        load_protocol(_write(tmp_path, PROTOCOL.replace(*change)))


def test_a_policy_trained_on_another_task_cannot_be_scored(tmp_path):
    protocol = load_protocol(_write(tmp_path, PROTOCOL))
    with pytest.raises(SuiteError, match="a policy trained on DebrisCapture-v1 cannot be scored"):
        protocol_suite(protocol, "DebrisCapture-v1", {})


def test_newcombe_interval_matches_the_published_examples():
    # Newcombe (1998), Statistics in Medicine 17:873, method 10 (score interval, no continuity correction)
    low, high = newcombe_interval(56, 70, 48, 80)
    assert low == pytest.approx(0.0524, abs=1e-4) and high == pytest.approx(0.3339, abs=1e-4)
    low, high = newcombe_interval(9, 10, 3, 10)
    assert low == pytest.approx(0.1705, abs=1e-4) and high == pytest.approx(0.8090, abs=1e-4)


def _report_row(name, successes, episodes):
    outcomes = [dict(success_at_end=i < successes) for i in range(episodes)]
    rate = successes / episodes
    return dict(configuration=name, summary=dict(episodes=episodes, success_at_end=rate, success_at_end_ci95=(rate, rate)), episodes=outcomes)


def test_a_row_reports_each_tests_gap_from_the_training_condition():
    row = matrix_row("p", {"domain": "mars", "sensor_configs": {}}, [_report_row(IN_DISTRIBUTION, 56, 70), _report_row("held-out", 48, 80)])
    assert row["label"] == "domain=mars" and row["training_condition"] == {"domain": "mars"}
    assert row["gaps"]["held-out"]["gap"] == pytest.approx(0.8 - 0.6)
    assert row["gaps"]["held-out"]["ci95"] == pytest.approx(newcombe_interval(56, 70, 48, 80))
    table = markdown_matrix(dict(protocol="x", metric="success_at_end", columns=[IN_DISTRIBUTION, "held-out"], rows=[row]))
    assert "| p | domain=mars | 80% [80, 80] | 60% [60, 60] |" in table and "+20 [+5, +33]" in table


def test_eval_scores_a_checkpoint_on_its_own_training_condition(tmp_path):
    model = BehaviourCloningPolicy(state_dim=49, action_dim=7, hidden=8, depth=1)
    trained = {"domain": "mars", "asset_source": "procedural", "num_levels": 3, "sensor_configs": {"shader_pack": "default"}}
    checkpoint = save_checkpoint(tmp_path / "bc.pt", "bc", model, dict(state_dim=49, action_dim=7, hidden=8, depth=1), "SampleCollection-v1", trained, "state", "pd_ee_delta_pose")
    output = tmp_path / "out"
    args = evaluation.Args(protocol=_write(tmp_path, PROTOCOL), policy=(f"checkpoint:{checkpoint}", "zero"), output_dir=output, num_workers=1)
    matrix = evaluation.main(args)
    assert matrix["columns"] == [IN_DISTRIBUTION, "held-out levels", "heavier"]
    learned, zero = matrix["rows"]
    assert learned["label"] == "domain=mars, asset_source=procedural, num_levels=3"
    assert zero["label"] == "domain=mars, asset_source=procedural, num_levels=2"  # the protocol's [train]
    assert set(learned["gaps"]) == {"held-out levels", "heavier"}
    assert json.loads((output / "matrix.json").read_text()) == json.loads(json.dumps(matrix))
    assert (output / "matrix.md").read_text().count("\n| ") >= 4 and (output / "matrix.png").stat().st_size > 0


def test_eval_needs_exactly_one_of_suite_and_protocol(tmp_path):
    with pytest.raises(UserError, match="give either --suite"):
        evaluation.main(evaluation.Args(policy=("zero",), output_dir=tmp_path))
