"""Every baseline runs end to end at a tiny size, writes its learning curve (CSV and PNG), and its checkpoint
scores in the evaluation CLI."""

import csv
import importlib.util
import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
import torch

from mani_skill_space import eval as evaluation
from mani_skill_space.learning import BestCheckpoint, CheckpointPolicy, DiffusionUnetNoisePredictor, load_demonstrations, set_learning_rate

ROOT = Path(__file__).resolve().parents[1]
ENV_KWARGS = {"domain": "mars", "asset_source": "dataset"}


def _baseline(name: str):
    spec = importlib.util.spec_from_file_location(f"baseline_{name}", ROOT / "baselines" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def demos(tmp_path_factory):
    """Two oracle demonstrations of SampleCollection, converted to pd_ee_delta_pose with state observations and their
    normalized dense rewards."""
    out = tmp_path_factory.mktemp("demos")
    subprocess.run(
        [sys.executable, "-m", "mani_skill_space.demos", "-e", "SampleCollection-v1", "-n", "2", "-j", "1", "--record-dir", str(out), "--traj-name", "tiny",
         "--env-kwargs", json.dumps(ENV_KWARGS)],
        check=True, cwd=ROOT,
    )  # fmt: skip
    raw = out / "SampleCollection-v1" / "motionplanning" / "tiny.h5"
    subprocess.run(
        [sys.executable, "-m", "mani_skill_space.replay", "--traj-path", str(raw), "-c", "pd_ee_delta_pose", "-o", "state", "--save-traj",
         "--record-rewards", "--reward-mode", "normalized_dense"],
        check=True, cwd=ROOT,
    )  # fmt: skip
    converted = sorted(raw.parent.glob("tiny.state.pd_ee_delta_pose*.h5"))
    assert converted, list(raw.parent.iterdir())
    return converted[0]


@pytest.fixture(scope="module")
def joint_demos(tmp_path_factory):
    """One oracle demonstration of SampleCollection in pd_joint_pos (absolute joint targets), with state observations."""
    out = tmp_path_factory.mktemp("joint_demos")
    subprocess.run(
        [sys.executable, "-m", "mani_skill_space.demos", "-e", "SampleCollection-v1", "-n", "1", "-j", "1", "--only-count-success", "-o", "state", "--record-dir", str(out),
         "--traj-name", "joint", "--env-kwargs", json.dumps(ENV_KWARGS)],
        check=True, cwd=ROOT,
    )  # fmt: skip
    return out / "SampleCollection-v1" / "motionplanning" / "joint.h5"


def _score(checkpoint: Path, tmp_path: Path) -> dict:
    suite = tmp_path / "suite.toml"
    suite.write_text(
        textwrap.dedent(
            """
            name = "baseline-check"
            episodes = 1
            seed_start = 20000
            [[configurations]]
            env_id = "SampleCollection-v1"
            kwargs = { domain = "mars", asset_source = "dataset" }
            """
        )
    )
    report = evaluation.main(evaluation.Args(suite=suite, policy=(f"checkpoint:{checkpoint}",), output_dir=tmp_path / "eval", num_workers=1))
    row = report["rows"][0]
    assert row["summary"]["episodes"] == 1
    assert (tmp_path / "eval" / "results.md").read_text().count("checkpoint:") == 1
    return row


def _curve(run_dir: Path) -> list[dict]:
    assert (run_dir / "curve.png").stat().st_size > 1000
    return list(csv.DictReader((run_dir / "curve.csv").open()))


def test_demonstrations_load_with_state_observations(demos):
    episodes, env_info = load_demonstrations(demos)
    assert env_info["env_id"] == "SampleCollection-v1"
    assert env_info["env_kwargs"]["control_mode"] == "pd_ee_delta_pose"
    for episode in episodes:
        assert len(episode["obs"]) == len(episode["actions"]) + 1
        assert episode["actions"].shape[1] == 7


def test_behaviour_cloning(demos, tmp_path):
    bc = _baseline("bc")
    checkpoint = bc.main(bc.Args(demos=demos, max_iterations=200, eval_every=100, eval_episodes=1, output_dir=tmp_path, name="bc"))
    rows = _curve(tmp_path / "bc")
    losses = [float(r["loss"]) for r in rows if r["loss"]]
    assert losses[-1] < losses[0]  # it learns something
    assert any(r["success_once"] != "" for r in rows)
    assert (tmp_path / "bc" / "best.pt").exists()  # the best of the training-time evaluations
    policy = CheckpointPolicy(str(checkpoint))
    assert (policy.control_mode, policy.obs_mode, policy.env_id) == ("pd_ee_delta_pose", "state", "SampleCollection-v1")
    _score(checkpoint, tmp_path)


def test_behaviour_cloning_observes_only_the_entries_it_is_given(demos, tmp_path):
    import gymnasium as gym

    from mani_skill_space.learning import state_layout

    env = gym.make("SampleCollection-v1", obs_mode="state_dict", control_mode="pd_ee_delta_pose", render_backend="none", **ENV_KWARGS)
    flat_env = gym.make("SampleCollection-v1", obs_mode="state", control_mode="pd_ee_delta_pose", render_backend="none", **ENV_KWARGS)
    entries, flat = env.reset(seed=0)[0], flat_env.reset(seed=0)[0]
    env.close()
    flat_env.close()
    layout = state_layout(entries)
    assert max(columns.stop for columns in layout.values()) == flat.shape[1]
    for name, columns in layout.items():  # each entry is where the layout says it is in the flat state
        group, key = name.split("/")
        torch.testing.assert_close(flat[:, columns], entries[group][key].reshape(1, -1).float())
    bc = _baseline("bc")
    checkpoint = bc.main(bc.Args(demos=demos, observe=("extra/tcp_pos", "agent/qpos"), max_iterations=20, eval_every=20, eval_episodes=0, output_dir=tmp_path, name="bc"))
    policy = CheckpointPolicy(str(checkpoint))
    wanted = [*range(layout["agent/qpos"].start, layout["agent/qpos"].stop), *range(layout["extra/tcp_pos"].start, layout["extra/tcp_pos"].stop)]
    assert policy.checkpoint["model_kwargs"]["observed"] == wanted
    assert policy.model.net[0].in_features == len(wanted) == 12
    _score(checkpoint, tmp_path)
    with pytest.raises(ValueError, match="Unknown state observation entry 'extra/tcp_position'; valid choices: agent/qpos, agent/qvel, extra/tcp_pos"):
        bc.main(bc.Args(demos=demos, observe=("extra/tcp_position",), max_iterations=1, eval_episodes=0, output_dir=tmp_path, name="bad"))


@pytest.mark.parametrize("learner", ["bc", "diffusion_policy"])
def test_imitation_learns_from_unsuccessful_demonstrations_only_when_asked(learner, demos, tmp_path, monkeypatch):
    out_of_time = tmp_path / "out_of_time.h5"
    shutil.copy(demos, out_of_time)
    meta = json.loads(demos.with_suffix(".json").read_text())
    for episode in meta["episodes"]:
        episode["success"] = False
    out_of_time.with_suffix(".json").write_text(json.dumps(meta))
    baseline = _baseline(learner)
    with pytest.raises(ValueError, match="holds no successful episodes"):
        baseline.main(baseline.Args(demos=out_of_time, max_iterations=2, eval_episodes=0, output_dir=tmp_path, name="refused"))

    loaded = []

    def load_and_count(*args, **kwargs):
        episodes, env_info = load_demonstrations(*args, **kwargs)
        loaded.append(len(episodes))
        return episodes, env_info

    monkeypatch.setattr(baseline, "load_demonstrations", load_and_count)
    checkpoint = baseline.main(baseline.Args(demos=out_of_time, unsuccessful_demos=True, max_iterations=20, eval_episodes=0, output_dir=tmp_path, name="learned"))
    assert loaded == [len(meta["episodes"])]  # every episode, none of them successful
    assert CheckpointPolicy(str(checkpoint)).env_id == "SampleCollection-v1"


def test_bc_balanced_action_loss_weighs_each_dimension_by_its_inverse_variance():
    bc = _baseline("bc")
    generator = torch.Generator().manual_seed(0)
    actions = torch.stack([torch.randn(1000, generator=generator) * 0.03, torch.randn(1000, generator=generator), torch.zeros(1000)], dim=1)
    weights = bc.action_loss_weights(actions)
    assert weights.mean().item() == pytest.approx(1.0)
    ratio = (weights[0] / weights[1]).item()
    assert ratio == pytest.approx((actions[:, 1].var() / actions[:, 0].var()).item(), rel=1e-4)  # about 1e3: the small one counts
    assert (weights[2] / weights[1]).item() == pytest.approx(actions[:, 1].var().item() / 1e-4, rel=1e-4)  # a constant one is capped


@pytest.mark.parametrize("schedule", ["constant", "cosine"])
def test_bc_learning_rate_schedule_follows_the_budget_that_ends_first(schedule):
    bc = _baseline("bc")
    args = bc.Args(demos=Path("unused.h5"), lr=1e-3, minutes=10.0, max_iterations=1000, lr_schedule=schedule)
    optimiser = torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=args.lr)
    rates = []
    for iteration, minutes in [(0, 0.0), (500, 1.0), (100, 5.0), (1000, 1.0), (10, 10.0)]:
        bc.set_learning_rate(optimiser, args, iteration, minutes)
        rates.append(optimiser.param_groups[0]["lr"])
    expected = [1e-3] * 5 if schedule == "constant" else [1e-3, 5e-4, 5e-4, 0.0, 0.0]
    assert rates == pytest.approx(expected, abs=1e-12)


def test_an_unknown_learning_rate_schedule_names_the_valid_ones():
    args = _baseline("bc").Args(demos=Path("unused.h5"), lr_schedule="linear")
    with pytest.raises(ValueError, match="valid choices: constant, cosine"):
        set_learning_rate(torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=args.lr), args, 0, 0.0)


@pytest.mark.parametrize("denoiser", ["mlp", "unet"])
def test_diffusion_policy(denoiser, demos, tmp_path):
    dp = _baseline("diffusion_policy")
    args = dp.Args(demos=demos, max_iterations=60, eval_every=30, eval_episodes=0, batch_size=32, diffusion_steps=10, keep_snapshots=True, denoiser=denoiser, output_dir=tmp_path, name="dp")
    checkpoint = dp.main(args)
    _curve(tmp_path / "dp")
    saved = torch.load(checkpoint, weights_only=True)
    assert saved["diffusion"]["inference_steps"] == 10
    assert saved["model_class"] == {"mlp": "DiffusionNoisePredictor", "unet": "DiffusionUnetNoisePredictor"}[denoiser]
    assert sorted(p.name for p in (tmp_path / "dp").glob("snapshot-*.pt")) == ["snapshot-30.pt", "snapshot-60.pt"]
    assert "scale_actions" not in saved["model_kwargs"] and "action_low" not in saved["state_dict"]  # delta actions, as they are
    snapshot = torch.load(tmp_path / "dp" / "snapshot-60.pt", weights_only=True)["state_dict"]
    assert snapshot.keys() == saved["state_dict"].keys() and all(torch.equal(snapshot[k], saved["state_dict"][k]) for k in snapshot)
    _score(checkpoint, tmp_path)


def test_the_diffusion_policy_scales_joint_targets_in_radians_from_their_range(joint_demos, tmp_path):
    dp = _baseline("diffusion_policy")
    tiny = dict(demos=joint_demos, eval_episodes=0, batch_size=8, diffusion_steps=5, hidden=32, output_dir=tmp_path)
    checkpoint = dp.main(dp.Args(**tiny, max_iterations=4, eval_every=4, ema=True, name="joint"))
    episodes, _ = load_demonstrations(joint_demos)
    demonstrated = torch.as_tensor(episodes[0]["actions"])
    assert demonstrated.abs().max() > 1.5  # the elbow's target, about -2 rad: outside the denoiser's [-1, 1]
    policy = CheckpointPolicy(str(checkpoint))
    assert policy.control_mode == "pd_joint_pos" and policy.model.scale_actions
    torch.testing.assert_close(policy.model.action_low, demonstrated.min(0).values)  # buffers, not averaged by the EMA
    torch.testing.assert_close(policy.model.action_high, demonstrated.max(0).values)
    policy.reset(SimpleNamespace(unwrapped=SimpleNamespace(spec=None)), seed=0)
    action = policy.act(torch.as_tensor(episodes[0]["obs"][:1]))  # (1, action_dim), in radians: within the demonstrated range
    assert ((action >= policy.model.action_low - 1e-5) & (action <= policy.model.action_high + 1e-5)).all()
    assert action.abs().max() > 1.5  # not clipped to [-1, 1]
    unscaled = dp.main(dp.Args(**tiny, max_iterations=1, eval_every=1, name="none", action_scaling="none"))
    assert not CheckpointPolicy(str(unscaled)).model.scale_actions


def test_the_denoisers_action_scaling_maps_the_unit_interval_onto_the_demonstrated_range():
    from mani_skill_space.learning import DiffusionNoisePredictor

    actions = torch.tensor([[-2.5, 0.3, 0.04], [3.0, 0.3, -0.01], [0.5, 0.3, 0.0]])
    for model in (DiffusionNoisePredictor(3, 3, 2, 8, hidden=8, scale_actions=True), DiffusionUnetNoisePredictor(3, 3, 2, 8, scale_actions=True)):
        model.fit_action_scaling(actions)
        unit = model.to_unit(actions)
        assert unit[:, 0].tolist() == pytest.approx([-1.0, 1.0, (0.5 - 0.25) / 2.75])
        assert unit[:, 1].tolist() == [0.0, 0.0, 0.0]  # a dimension that never varies sits at the centre
        assert unit.abs().max() <= 1.0 + 1e-6
        torch.testing.assert_close(model.from_unit(unit), actions)
        torch.testing.assert_close(model.from_unit(torch.ones(3)), torch.tensor([3.0, 0.3, 0.04]))
    plain = DiffusionNoisePredictor(3, 3, 2, 8, hidden=8)
    assert "action_low" not in plain.state_dict()  # what checkpoints saved without scaling hold (dp_tubes_dart.pt loads: above)
    assert torch.equal(plain.to_unit(actions), actions) and torch.equal(plain.from_unit(actions), actions)


def test_the_diffusion_policy_samples_its_chunks_from_noise_seeded_by_the_episode():
    policy = CheckpointPolicy(str(ROOT / "baselines" / "checkpoints" / "dp_tubes_dart.pt"))
    env = SimpleNamespace(unwrapped=SimpleNamespace(spec=SimpleNamespace(id=policy.env_id)))
    observations = torch.randn(9, 1, policy.model.state_dim, generator=torch.Generator().manual_seed(0))

    def rollout(seed: int, global_seed: int = 0) -> torch.Tensor:
        policy.reset(env, seed)
        torch.manual_seed(global_seed)  # the global generator's state must not matter
        return torch.stack([policy.act(obs) for obs in observations])

    assert torch.equal(rollout(3, global_seed=0), rollout(3, global_seed=1))
    assert not torch.allclose(rollout(3), rollout(4))


def test_the_unet_denoiser_predicts_a_chunk_per_sample_conditioned_on_its_own_step_and_history():
    unet = DiffusionUnetNoisePredictor(state_dim=5, action_dim=3, obs_horizon=2, action_horizon=8).eval()
    chunks, steps, history = torch.randn(4, 8, 3), torch.tensor([0, 10, 50, 99]), torch.randn(4, 2, 5)
    noise = unet(chunks, steps, history)
    assert noise.shape == (4, 8, 3)
    alone = torch.cat([unet(chunks[i : i + 1], steps[i : i + 1], history[i : i + 1]) for i in range(4)])
    assert torch.allclose(noise, alone, atol=1e-5)  # no sample's prediction depends on another's (group norm, not batch norm)
    assert not torch.allclose(noise[:1], unet(chunks[:1], steps[1:2], history[:1]))  # the step conditions it
    assert not torch.allclose(noise[:1], unet(chunks[:1], steps[:1], history[1:2]))  # the history conditions it
    assert unet(chunks[:1], torch.tensor(7), history[:1]).shape == (1, 8, 3)  # one step for the batch, as at inference
    with pytest.raises(ValueError, match="divisible by 4"):
        DiffusionUnetNoisePredictor(state_dim=5, action_dim=3, obs_horizon=2, action_horizon=6)


def test_the_diffusion_policy_samples_observation_windows_and_action_chunks_padded_at_the_episode_ends():
    dp = _baseline("diffusion_policy")
    episode = {"obs": np.arange(4, dtype=np.float32)[:, None], "actions": 10 + np.arange(3, dtype=np.float32)[:, None]}  # 3 steps
    obs, actions = dp.chunk_windows([episode, episode], obs_horizon=2, action_horizon=3)
    assert obs.shape == (6, 2, 1) and actions.shape == (6, 3, 1)
    assert obs[:3, :, 0].tolist() == [[0, 0], [0, 1], [1, 2]]  # the first observation repeated before the start
    assert actions[:3, :, 0].tolist() == [[10, 11, 12], [11, 12, 12], [12, 12, 12]]  # the last action repeated after the end
    assert torch.equal(obs[3:], obs[:3]) and torch.equal(actions[3:], actions[:3])


def test_diffusion_policy_trains_a_compiled_denoiser_and_saves_the_plain_one(demos, tmp_path):
    dp = _baseline("diffusion_policy")
    args = dp.Args(demos=demos, max_iterations=5, eval_every=5, eval_episodes=0, batch_size=8, diffusion_steps=10, hidden=32, output_dir=tmp_path, compile="default", ema=True)
    path = dp.main(args)
    assert not any(key.startswith("_orig_mod") for key in torch.load(path, weights_only=True)["state_dict"])
    assert CheckpointPolicy(str(path)).diffusion is not None  # loads into the plain denoiser


def test_diffusion_policy_saves_the_moving_average_of_its_weights_with_ema(demos, tmp_path):
    dp = _baseline("diffusion_policy")
    tiny = dict(demos=demos, max_iterations=30, eval_every=30, eval_episodes=0, batch_size=16, diffusion_steps=10, output_dir=tmp_path, lr_schedule="cosine", obs_noise=0.05)
    trained = torch.load(dp.main(dp.Args(**tiny, name="plain")), weights_only=True)["state_dict"]
    averaged = torch.load(dp.main(dp.Args(**tiny, name="ema", ema=True)), weights_only=True)["state_dict"]
    assert trained.keys() == averaged.keys()
    assert torch.equal(trained["obs_mean"], averaged["obs_mean"])  # buffers are not averaged
    weights = [key for key in trained if key.startswith("net.") and key.endswith("weight")]
    assert weights and all(not torch.allclose(trained[key], averaged[key]) for key in weights)


@pytest.mark.parametrize("obs_mode", ["state", "rgbd"])
def test_ppo(obs_mode, tmp_path):
    ppo = _baseline("ppo")
    steps = 160 if obs_mode == "state" else 8  # state: long enough for every env to finish an episode
    checkpoint = ppo.main(
        ppo.Args(env_kwargs=json.dumps(ENV_KWARGS), obs_mode=obs_mode, num_envs=2, num_steps=steps, total_timesteps=2 * steps, output_dir=tmp_path, name="ppo")
    )
    rows = _curve(tmp_path / "ppo")
    assert len(rows) == 1
    if obs_mode == "state":
        assert int(rows[0]["episodes"]) == 2 and float(rows[0]["return"]) > 0
    assert CheckpointPolicy(str(checkpoint)).obs_mode == obs_mode
    _score(checkpoint, tmp_path)


def test_sac(tmp_path):
    sac = _baseline("sac")
    checkpoint = sac.main(
        sac.Args(env_kwargs=json.dumps(ENV_KWARGS), num_envs=2, total_timesteps=320, learning_starts=100, batch_size=64, buffer_size=1000, log_every=100, output_dir=tmp_path, name="sac")
    )
    rows = _curve(tmp_path / "sac")
    assert any(r["episodes"] not in ("", "0") for r in rows)
    _score(checkpoint, tmp_path)


def test_rlpd_learns_from_the_sparse_reward_with_half_of_each_batch_from_the_demonstrations(demos, tmp_path):
    sac = _baseline("sac")
    args = sac.Args(
        env_kwargs=json.dumps(ENV_KWARGS), num_envs=2, total_timesteps=320, learning_starts=100, batch_size=64, buffer_size=1000, log_every=100,
        output_dir=tmp_path, name="rlpd", reward_mode="sparse", demos=demos, critic_layer_norm=True,
    )  # fmt: skip
    transitions = sac.demonstration_transitions(args, ENV_KWARGS, torch.device("cpu"))
    episodes, _ = load_demonstrations(demos)
    assert len(transitions["state"]) == sum(len(e["actions"]) for e in episodes)
    assert transitions["reward"].sum().item() == sum(e["success"].sum() for e in episodes) > 0  # the sparse reward: 1 where solved
    checkpoint = sac.main(args)
    assert torch.load(checkpoint, weights_only=True)["algorithm"] == "rlpd"
    assert any(r["episodes"] not in ("", "0") for r in _curve(tmp_path / "rlpd"))
    _score(checkpoint, tmp_path)


def test_rlpd_on_the_dense_reward_takes_the_rewards_the_demonstrations_recorded(demos):
    sac = _baseline("sac")
    args = sac.Args(env_kwargs=json.dumps(ENV_KWARGS), demos=demos, reward_mode="normalized_dense")
    transitions = sac.demonstration_transitions(args, ENV_KWARGS, torch.device("cpu"))
    episodes, _ = load_demonstrations(demos)
    recorded = torch.as_tensor(np.concatenate([e["rewards"] for e in episodes]))
    assert torch.equal(transitions["reward"], recorded)
    sparse = sac.demonstration_transitions(sac.Args(env_kwargs=json.dumps(ENV_KWARGS), demos=demos, reward_mode="sparse"), ENV_KWARGS, torch.device("cpu"))
    assert recorded.max() <= 1 and (recorded[sparse["reward"] == 0] > 0).any()  # the dense reward pays before the success


def test_rlpd_refuses_demonstrations_without_the_reward_or_of_another_task(demos, tmp_path):
    sac = _baseline("sac")
    with pytest.raises(ValueError, match="--reward-mode dense needs demonstrations that record that reward .* the normalized_dense reward"):
        sac.demonstration_transitions(sac.Args(env_kwargs=json.dumps(ENV_KWARGS), demos=demos, reward_mode="dense"), ENV_KWARGS, torch.device("cpu"))
    unrewarded = tmp_path / demos.name
    shutil.copy(demos, unrewarded)
    shutil.copy(demos.with_suffix(".json"), unrewarded.with_suffix(".json"))
    with h5py.File(unrewarded, "r+") as data:
        for trajectory in data.values():
            del trajectory["rewards"]
    with pytest.raises(ValueError, match="records no rewards.*--record-rewards --reward-mode normalized_dense"):
        sac.demonstration_transitions(sac.Args(env_kwargs=json.dumps(ENV_KWARGS), demos=unrewarded), ENV_KWARGS, torch.device("cpu"))
    moon = dict(ENV_KWARGS, domain="moon")
    with pytest.raises(ValueError, match="holds demonstrations of"):
        sac.demonstration_transitions(sac.Args(env_kwargs=json.dumps(moon), demos=demos, reward_mode="sparse"), moon, torch.device("cpu"))


def test_rlpd_batches_are_half_demonstrations():
    sac = _baseline("sac")
    own = {key: torch.zeros(100, 3) for key in ("state", "action", "reward", "next_state", "terminated")}
    demos = {key: torch.ones(10, 3) for key in own}
    batch = sac.sample_batch(own, 50, demos, 64)
    assert all(len(values) == 64 for values in batch.values())
    assert batch["state"][:, 0].sum().item() == 32
    assert sac.sample_batch(own, 50, None, 64)["state"].sum().item() == 0


def test_checkpoint_of_another_task_is_refused(tmp_path, demos):
    bc = _baseline("bc")
    checkpoint = bc.main(bc.Args(demos=demos, max_iterations=10, eval_every=10, eval_episodes=0, output_dir=tmp_path, name="bc"))
    import gymnasium as gym

    env = gym.make("PegInHoleAssembly-v1", render_backend="none")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="trained on SampleCollection-v1"):
        CheckpointPolicy(str(checkpoint)).reset(env, 0)
    env.close()


def test_the_best_checkpoint_is_kept_by_success_at_end_then_success_once_then_return(tmp_path):
    checkpoint = tmp_path / "checkpoint.pt"
    best = BestCheckpoint(checkpoint)
    evaluations = [  # (success_at_end, success_once, return), whether it is the best so far
        ((0.2, 0.3, 10.0), True),
        ((0.1, 0.9, 50.0), False),
        ((0.2, 0.3, 12.0), True),
        ((0.2, 0.3, 12.0), False),  # a tie keeps the earlier checkpoint
        ((0.4, 0.4, 1.0), True),
    ]
    for version, (scores, is_best) in enumerate(evaluations):
        checkpoint.write_text(str(version))
        assert best.update(dict(zip(BestCheckpoint.KEYS, scores))) == is_best
    assert best.path == tmp_path / "best.pt" and best.path.read_text() == "4"


def test_diversity_curve_scores_each_checkpoint_on_the_protocol_and_counts_its_levels(tmp_path):
    from mani_skill_space.learning import BehaviourCloningPolicy, save_checkpoint

    protocol = tmp_path / "levels.toml"
    protocol.write_text(
        textwrap.dedent(
            """
            name = "levels-check"
            episodes = 1
            seed_start = 20000
            [train]
            env_id = "SampleCollection-v1"
            kwargs = { domain = "mars", asset_source = "procedural", num_levels = 10 }
            [[tests]]
            name = "held-out levels"
            kwargs = { num_levels = 0, start_level = 1000000 }
            """
        )
    )
    checkpoints, demos = [], []
    for num_levels in (1, 3):
        model_kwargs = dict(state_dim=49, action_dim=7, hidden=8, depth=1)
        kwargs = dict(domain="mars", asset_source="procedural", num_levels=num_levels, start_level=0)
        checkpoints.append(save_checkpoint(tmp_path / f"bc{num_levels}.pt", "bc", BehaviourCloningPolicy(**model_kwargs), model_kwargs, "SampleCollection-v1", kwargs, "state", "pd_ee_delta_pose"))
        demos.append(tmp_path / f"levels{num_levels}.h5")
        episodes = [dict(episode_id=i, episode_seed=seed, success=seed != 7) for i, seed in enumerate(range(8))]
        demos[-1].with_suffix(".json").write_text(json.dumps(dict(env_info={}, episodes=episodes)))
    curve = _baseline("diversity_curve")
    rows = curve.main(curve.Args(checkpoints=tuple(checkpoints), demos=tuple(demos), protocol=str(protocol), output=tmp_path / "curve", num_workers=1))
    assert [(r["num_levels"], r["demonstrations"]) for r in rows] == [(1, 7), (3, 7)]
    assert rows[0]["levels_in_demos"] == 1 and 1 < rows[1]["levels_in_demos"] <= 3
    assert {"train: success", "held-out levels: success", "gap held-out levels: ci_low"} <= set(rows[0])
    assert (tmp_path / "curve.csv").read_text().count("\n") == 3 and (tmp_path / "curve.png").stat().st_size > 0
    assert (tmp_path / "curve_matrix.md").is_file()
