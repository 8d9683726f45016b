"""DAgger on Solar Panel Assembly: the push expert's geometry, its labels on a policy's own rollout, and BC
learning from labelled states (from a checkpoint it starts from)."""

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from mani_skill_space.learning import CheckpointPolicy, load_labelled_states
from mani_skill_space.oracles.end_effector import ROTATION_SPEED_FRACTION, TRANSLATION_SPEED_FRACTION
from mani_skill_space.oracles.push_expert import (
    HOVER_GAP,
    InsertionPushExpert,
    nearest_twist,
    shortest_turn_onto_z,
    slowed,
)
from mani_skill_space.oracles.insertion import PRESS_DEPTH, SEATING_STEP
from tests.test_baselines import _baseline, demos  # noqa: F401  (the fixture)

ROOT = Path(__file__).resolve().parents[1]
SOLAR_BC = ROOT / "baselines" / "checkpoints" / "bc_solar_ee.pt"


def _rotation(axis, angle):
    return Rotation.from_rotvec(angle * np.asarray(axis, dtype=float) / np.linalg.norm(axis)).as_matrix()


@pytest.mark.parametrize("axis", [[1, 0, 0], [0.3, -0.8, 0.2], [0, 0, -1], [0, 0, 1], [1e-12, 0, 1]])
def test_the_shortest_turn_takes_any_axis_onto_z(axis):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    turn = shortest_turn_onto_z(axis)
    np.testing.assert_allclose(turn @ axis, [0, 0, 1], atol=1e-9)
    np.testing.assert_allclose(turn @ turn.T, np.eye(3), atol=1e-9)
    assert np.linalg.det(turn) == pytest.approx(1.0)


def test_the_nearest_twist_snaps_to_the_profiles_symmetry_even_for_a_peg_lying_across():
    end = np.eye(4)
    end[:3, :3] = _rotation([0, 0, 1], np.radians(50))
    assert nearest_twist(end, 4) == pytest.approx(np.pi / 2)  # 50 deg: nearer 90 than 0
    assert nearest_twist(end, 0) == pytest.approx(np.radians(50))  # a round peg keeps its own
    lying = end.copy()
    lying[:3, :3] = _rotation([1, 0, 0], np.radians(85)) @ _rotation([0, 0, 1], np.radians(-20))
    assert nearest_twist(lying, 4) == pytest.approx(0.0, abs=1e-9)  # turned upright the shortest way first


def test_slowed_actions_keep_to_a_share_of_the_controllers_limits():
    action = slowed(np.array([0.9, -0.05, -1.0, 0.6, 0.8, 0.0]))
    np.testing.assert_allclose(action[:3], [TRANSLATION_SPEED_FRACTION, -0.05, -TRANSLATION_SPEED_FRACTION])
    assert np.linalg.norm(action[3:]) == pytest.approx(ROTATION_SPEED_FRACTION)
    np.testing.assert_allclose(action[3:] / np.linalg.norm(action[3:]), [0.6, 0.8, 0.0])  # the turn's direction kept
    np.testing.assert_allclose(slowed(np.array([0.9, 0, 0, 0, 0, 0]), 0.1)[:3], [0.1, 0, 0])


@pytest.mark.parametrize(
    "lateral, angle, tip, expected",
    [
        (0.002, 0.0, 0.03, 0.03),  # above the entrance, off the axis: line up where it is
        (0.002, 0.0, 0.021, 0.02 + HOVER_GAP),  # just above: rise to the hover gap first
        (0.0003, 0.0, 0.03, 0.026),  # lined up above: down the axis
        (0.0003, 0.0, 0.01, 0.006),  # in the socket: a step ahead of the tip
        (0.0003, 0.0, 0.005, 0.005 - SEATING_STEP),  # near the bottom: smaller steps
        (0.0003, 0.0, 0.0, -PRESS_DEPTH),  # at the bottom: keep pressing
        (0.006, 0.0, 0.01, 0.02 + HOVER_GAP),  # below the entrance's plane, beside the socket: back up
    ],
)
def test_the_push_goes_down_the_axis_once_lined_up(lateral, angle, tip, expected):
    goal = InsertionPushExpert._goal_height(dict(lateral_offset=lateral, axis_angle=angle), tip, depth=0.02)
    assert goal == pytest.approx(expected)


def test_dagger_labels_a_policys_own_states_with_the_peg_in_the_hand(tmp_path):
    dagger = _baseline("dagger")
    output = tmp_path / "labels.h5"
    meta = dagger.collect(dagger.Args(checkpoint=SOLAR_BC, output=output, seed_start=5000, episodes=1, expert_share=1.0, max_episode_steps=70))
    obs, actions, env_info = load_labelled_states(output)
    assert env_info["env_id"] == "SolarPanelAssembly-v1" and env_info["env_kwargs"]["control_mode"] == "pd_ee_delta_pose"
    # BC grasps the first peg at step 41-44 on this seed; from then on the expert lifts it, gripper closed
    assert meta["episodes"][0]["labelled_steps"] == len(obs) > 10
    assert obs.shape[1] == CheckpointPolicy(str(SOLAR_BC)).checkpoint["model_kwargs"]["state_dim"]
    assert np.all(actions[:, -1] == -1.0)
    assert np.all(actions[:, 2] > 0)  # up
    assert np.all(np.abs(actions[:, :3]) <= TRANSLATION_SPEED_FRACTION + 1e-6)
    assert np.all(np.linalg.norm(actions[:, 3:6], axis=1) <= ROTATION_SPEED_FRACTION + 1e-6)


def test_dagger_refuses_a_policy_of_a_task_it_has_no_expert_for(tmp_path):
    dagger = _baseline("dagger")
    with pytest.raises(ValueError, match="labels SolarPanelAssembly-v1; .* SampleCollection-v1"):
        dagger.collect(dagger.Args(checkpoint=ROOT / "baselines" / "checkpoints" / "bc_tubes.pt", output=tmp_path / "x.h5", episodes=1))
    with pytest.raises(ValueError, match="--expert-share must be within"):
        dagger.collect(dagger.Args(checkpoint=SOLAR_BC, output=tmp_path / "x.h5", expert_share=1.5))


def _labelled_copy(demos: Path, path: Path, env_id: str = None) -> Path:
    """The demonstrations' states and actions written as labelled states (the format dagger.py writes)."""
    meta = json.loads(demos.with_suffix(".json").read_text())
    with h5py.File(demos) as data, h5py.File(path, "w") as out:
        out["obs"] = np.asarray(data["traj_0"]["obs"])[:-1]
        out["actions"] = np.asarray(data["traj_0"]["actions"])
    env_info = dict(meta["env_info"], env_id=env_id or meta["env_info"]["env_id"])
    path.with_suffix(".json").write_text(json.dumps(dict(env_info=env_info, episodes=[])))
    return path


def test_bc_learns_from_labelled_states_starting_from_a_checkpoint(demos, tmp_path):  # noqa: F811
    bc = _baseline("bc")
    start = bc.main(bc.Args(demos=demos, max_iterations=20, eval_episodes=0, output_dir=tmp_path, name="start"))
    labelled = _labelled_copy(demos, tmp_path / "labels.h5")
    tuned = bc.main(
        bc.Args(demos=demos, labelled_states=(labelled,), labelled_share=0.5, init_checkpoint=start, max_iterations=20, eval_episodes=0, output_dir=tmp_path, name="tuned")
    )
    before, after = torch.load(start, weights_only=True), torch.load(tuned, weights_only=True)
    assert after["model_kwargs"] == before["model_kwargs"]
    torch.testing.assert_close(after["state_dict"]["obs_mean"], before["state_dict"]["obs_mean"])  # its normalisation kept
    assert any(not torch.equal(after["state_dict"][k], before["state_dict"][k]) for k in before["state_dict"])

    with pytest.raises(ValueError, match="was labelled on .*PegInHoleAssembly-v1"):
        bc.main(bc.Args(demos=demos, labelled_states=(_labelled_copy(demos, tmp_path / "other.h5", "PegInHoleAssembly-v1"),), max_iterations=2, eval_episodes=0, output_dir=tmp_path))
    with pytest.raises(ValueError, match="--init-checkpoint .* expected bc on SampleCollection-v1"):
        bc.main(bc.Args(demos=demos, init_checkpoint=SOLAR_BC, max_iterations=2, eval_episodes=0, output_dir=tmp_path))


def test_bc_batches_take_their_share_of_labelled_states():
    bc = _baseline("bc")
    batch = bc.batch_sampler(1000, 10, 0.25, 64)()
    assert len(batch) == 64 and int((batch >= 1000).sum()) == 16 and int(batch.max()) < 1010
    assert len(bc.batch_sampler(1000, 0, None, 64)()) == 64
    with pytest.raises(ValueError, match="--labelled-share needs --labelled-states"):
        bc.batch_sampler(1000, 0, 0.25, 64)
    with pytest.raises(ValueError, match="--labelled-share must be within"):
        bc.batch_sampler(1000, 10, 1.0, 64)
