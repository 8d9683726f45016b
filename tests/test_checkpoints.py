"""Checkpoint files never execute code when loaded, and a bad file is named in a clear error."""

import os

import pytest
import torch

from mani_skill_space.learning import BehaviourCloningPolicy, CheckpointError, CheckpointPolicy, load_checkpoint, save_checkpoint


class _RunsCode:
    """Unpickling this object would create ``path`` (what a crafted checkpoint could do instead)."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (os.mkdir, (self.path,))


def test_a_crafted_checkpoint_does_not_run_code(tmp_path):
    marker = tmp_path / "pwned"
    crafted = tmp_path / "crafted.pt"
    torch.save({"algorithm": "bc", "payload": _RunsCode(marker)}, crafted)
    with pytest.raises(CheckpointError, match="crafted.pt"):
        CheckpointPolicy(str(crafted))
    assert not marker.exists()


@pytest.mark.parametrize("content", [b"", b"not a checkpoint at all", b"PK\x03\x04garbage"], ids=["empty", "text", "corrupt-zip"])
def test_unreadable_files_are_named(tmp_path, content):
    path = tmp_path / "model.pt"
    path.write_bytes(content)
    with pytest.raises(CheckpointError, match="model.pt"):
        load_checkpoint(path)


def test_a_foreign_checkpoint_is_refused(tmp_path):
    path = tmp_path / "weights.pt"
    torch.save({"weight": torch.zeros(3)}, path)
    with pytest.raises(CheckpointError, match="weights.pt.*not a mani-skill-space checkpoint"):
        load_checkpoint(path)


def test_a_checkpoint_whose_model_does_not_fit_this_version_is_named(tmp_path):
    model = BehaviourCloningPolicy(state_dim=5, action_dim=2, hidden=8, depth=1)
    foreign_kwargs = save_checkpoint(tmp_path / "kwargs.pt", "bc", model, dict(state_dim=5, action_dim=2, hidden=8, depth=1, width_scale=2), "SampleCollection-v1", {}, "state", "pd_ee_delta_pose")
    with pytest.raises(CheckpointError, match=r"kwargs.pt does not fit this version's BehaviourCloningPolicy \(.*width_scale"):
        CheckpointPolicy(str(foreign_kwargs))
    other_shapes = save_checkpoint(tmp_path / "shapes.pt", "bc", model, dict(state_dim=5, action_dim=2, hidden=16, depth=1), "SampleCollection-v1", {}, "state", "pd_ee_delta_pose")
    with pytest.raises(CheckpointError, match="shapes.pt does not fit"):
        CheckpointPolicy(str(other_shapes))


def test_a_missing_checkpoint_is_named(tmp_path):
    with pytest.raises(CheckpointError, match="nothing.pt"):
        CheckpointPolicy(str(tmp_path / "nothing.pt"))


def test_saved_checkpoints_load_safely(tmp_path):
    model = BehaviourCloningPolicy(state_dim=5, action_dim=2, hidden=8, depth=1)
    path = save_checkpoint(tmp_path / "bc.pt", "bc", model, dict(state_dim=5, action_dim=2, hidden=8, depth=1), "SampleCollection-v1", {"domain": "mars"}, "state", "pd_ee_delta_pose")
    policy = CheckpointPolicy(str(path))
    assert policy.env_id == "SampleCollection-v1" and policy.control_mode == "pd_ee_delta_pose"
    torch.testing.assert_close(policy.model.net[0].weight, model.net[0].weight)


def test_the_crafted_file_really_runs_code_without_weights_only(tmp_path):
    """The control for the test above: the same file, loaded the unsafe way, does run its payload."""
    marker = tmp_path / "pwned"
    crafted = tmp_path / "crafted.pt"
    torch.save({"payload": _RunsCode(marker)}, crafted)
    torch.load(crafted, weights_only=False)
    assert marker.exists()


def test_observations_of_another_size_are_refused_by_name(tmp_path):
    kwargs = dict(state_dim=5, action_dim=2, hidden=8, depth=1)
    path = save_checkpoint(tmp_path / "stale.pt", "bc", BehaviourCloningPolicy(**kwargs), kwargs, "SampleCollection-v1", {}, "state", "pd_ee_delta_pose")
    policy = CheckpointPolicy(str(path))
    assert policy.act(torch.zeros(1, 5)).shape == (1, 2)
    with pytest.raises(CheckpointError, match="stale.pt takes 5 state observations and this version of SampleCollection-v1 gives 6"):
        policy.act(torch.zeros(1, 6))


def test_a_policy_of_some_columns_ignores_the_others_and_loads_with_them(tmp_path):
    kwargs = dict(state_dim=6, action_dim=2, hidden=8, depth=1, observed=[1, 4])
    model = BehaviourCloningPolicy(**kwargs)
    assert model.net[0].in_features == 2
    states = torch.randn(8, 6)
    others_changed = states.clone()
    others_changed[:, [0, 2, 3, 5]] = torch.randn(8, 4)
    torch.testing.assert_close(model(states), model(others_changed))
    observed_changed = states.clone()
    observed_changed[:, 4] += 1.0
    assert not torch.allclose(model(states), model(observed_changed))
    policy = CheckpointPolicy(str(save_checkpoint(tmp_path / "some.pt", "bc", model, kwargs, "SampleCollection-v1", {}, "state", "pd_ee_delta_pose")))
    torch.testing.assert_close(policy.act(states), model(states))


def test_observed_columns_outside_the_state_are_refused():
    with pytest.raises(ValueError, match=r"observed columns must lie in \[0, 6\)"):
        BehaviourCloningPolicy(state_dim=6, action_dim=2, observed=[2, 6])


def test_the_state_layout_follows_maniskills_flattening_order():
    from mani_skill_space.learning import observed_dims, state_layout

    obs = {"agent": {"qpos": torch.zeros(8, 3), "qvel": torch.zeros(8, 3)}, "extra": {"gripper": torch.zeros(8), "goal": torch.zeros(8, 2)}}
    layout = state_layout(obs)
    assert layout == {"agent/qpos": slice(0, 3), "agent/qvel": slice(3, 6), "extra/gripper": slice(6, 7), "extra/goal": slice(7, 9)}
    assert observed_dims(layout, ["extra/goal", "agent/qpos"]) == [0, 1, 2, 7, 8]
    with pytest.raises(ValueError, match="Unknown state observation entry 'extra/gaol'; valid choices: agent/qpos, agent/qvel, extra/gripper, extra/goal"):
        observed_dims(layout, ["extra/gaol"])
