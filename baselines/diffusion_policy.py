"""Diffusion policy (Chi et al. 2023) from oracle demonstrations, state observations, following ManiSkill's
``examples/baselines/diffusion_policy``: a DDPM (diffusers' scheduler) denoises a chunk of future actions
conditioned on the last observations; the policy executes the first few actions of each chunk.

    python baselines/diffusion_policy.py --demos demos/.../<name>.state.pd_ee_delta_pose.physx_cpu.h5

Demonstrations as for ``bc.py``. Writes ``runs/<name>/curve.csv``, ``curve.png``, ``checkpoint.pt`` (the last) and
``best.pt`` (the best in the training-time evaluations) for ``python -m mani_skill_space.eval --policy
checkpoint:PATH``.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Optional

import numpy as np
import torch
import tyro
from diffusers.schedulers.scheduling_ddpm import DDPMScheduler
from diffusers.training_utils import EMAModel
from tqdm import tqdm

from mani_skill_space.learning import (
    BestCheckpoint,
    CheckpointPolicy,
    DiffusionNoisePredictor,
    DiffusionUnetNoisePredictor,
    LearningCurve,
    LrSchedule,
    load_demonstrations,
    save_checkpoint,
    set_learning_rate,
    task_of_demonstrations,
)


@dataclass
class Args:
    demos: Path
    """A ManiSkill trajectory file with state observations (converted with the replay tool)."""
    num_demos: Optional[int] = None
    """Use only the first N successful demonstrations (the first N, with ``--unsuccessful-demos``)."""
    unsuccessful_demos: bool = False
    """Learn from every demonstration in the file, not only the successful ones: for a task whose demonstrations end
    before success (Solar Panel Assembly's in ``pd_ee_delta_pose``: out of time, or stopped by a planning failure, with
    one to three of the four sockets filled), the part of the task they do show."""
    obs_horizon: int = 2
    action_horizon: int = 8
    """Actions predicted per chunk."""
    execute_horizon: int = 4
    """Actions of each chunk executed before predicting the next."""
    diffusion_steps: int = 100
    minutes: float = 30.0
    max_iterations: int = 100_000
    batch_size: int = 256
    lr: float = 1e-4
    lr_schedule: LrSchedule = "constant"
    """``cosine`` decays the learning rate to zero over the budget (``--minutes`` or ``--max-iterations``, whichever
    ends first), as ManiSkill's diffusion policy does over its iterations."""
    ema: bool = False
    """Evaluate and save an exponential moving average of the weights (diffusers' ``EMAModel``, as ManiSkill's
    diffusion policy: its decay grows as (1 + k) / (10 + k) with the update k, to at most 0.9999)."""
    obs_noise: float = 0.0
    """Gaussian noise (in units of each observation's standard deviation) added to the observations the chunks
    are conditioned on in training, as ``bc.py``'s ``--obs-noise``."""
    denoiser: Literal["mlp", "unet"] = "mlp"
    """``mlp``: an MLP over the flattened chunk (``DiffusionNoisePredictor``, ``--hidden`` wide); ``unet``: Chi et al.'s
    1-D UNet over the chunk's time axis, FiLM-conditioned (``DiffusionUnetNoisePredictor``, as ManiSkill's baseline;
    ``--action-horizon`` a multiple of 4)."""
    hidden: int = 512
    action_scaling: Literal["auto", "none", "min-max"] = "auto"
    """How the demonstrated actions map to the [-1, 1] the denoiser works in (DDPM clips its samples there):
    ``min-max`` scales every dimension from the demonstrations' range (Chi et al.); ``none`` takes them as they are
    (ManiSkill's normalised delta modes, e.g. ``pd_ee_delta_pose``); ``auto`` is ``min-max`` where any demonstrated
    action lies outside [-1, 1] (``pd_joint_pos``'s joint targets in radians), ``none`` otherwise."""
    eval_every: int = 5000
    eval_episodes: int = 10
    eval_seed_start: int = 10_000
    keep_snapshots: bool = False
    """Also keep the checkpoint of every evaluation point as ``snapshot-<iteration>.pt``, to select among them
    afterwards (e.g. after training with ``--eval-episodes 0`` on a machine without the simulator)."""
    compile: Literal["off", "default", "reduce-overhead"] = "off"
    """``torch.compile`` the denoiser for training with this mode: ``reduce-overhead`` replays CUDA graphs for the
    UNet's many small kernels (on an H200, two UNet runs at once: 55-67 iterations a second each, against about 40
    uncompiled); ``default`` fuses kernels without graphs. The first iterations pay the compilation."""
    device: str = "auto"
    """``auto``: CUDA where torch finds it, else the CPU. Checkpoints are saved with CPU tensors either way."""
    output_dir: Path = Path("runs")
    name: Optional[str] = None
    seed: int = 0


def chunk_windows(episodes, obs_horizon: int, action_horizon: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Every training sample, one per (episode, start step): the observations up to the start step and the actions
    from it; windows reaching past an episode's ends are padded with its first observation / last action."""
    obs, actions = [], []
    for episode in episodes:
        length = len(episode["actions"])
        starts = np.arange(length)[:, None]
        obs.append(episode["obs"][np.clip(starts + np.arange(1 - obs_horizon, 1), 0, length)])
        actions.append(episode["actions"][np.clip(starts + np.arange(action_horizon), 0, length - 1)])
    return torch.as_tensor(np.concatenate(obs)), torch.as_tensor(np.concatenate(actions))


def scales_actions(action_scaling: str, actions: torch.Tensor) -> bool:
    """Whether ``--action-scaling`` asks for min-max scaling of these demonstrated actions."""
    return action_scaling == "min-max" or (action_scaling == "auto" and bool((actions.abs() > 1).any()))


def evaluate(policy, env_id: str, env_kwargs: dict, seeds) -> dict[str, float]:
    from mani_skill_space.rollout import evaluate_policy  # the simulator only where training evaluates

    return evaluate_policy(policy, env_id, env_kwargs, seeds)


def main(args: Args) -> Path:
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    episodes, env_info = load_demonstrations(args.demos, success_only=not args.unsuccessful_demos, limit=args.num_demos)
    env_id, env_kwargs, obs_mode, control_mode = task_of_demonstrations(env_info)
    device = torch.device(("cuda" if torch.cuda.is_available() else "cpu") if args.device == "auto" else args.device)
    all_obs = np.concatenate([e["obs"] for e in episodes])
    sample_obs, sample_actions = (x.to(device) for x in chunk_windows(episodes, args.obs_horizon, args.action_horizon))
    model_kwargs = dict(state_dim=all_obs.shape[1], action_dim=episodes[0]["actions"].shape[1], obs_horizon=args.obs_horizon, action_horizon=args.action_horizon)
    if scales_actions(args.action_scaling, sample_actions):
        model_kwargs["scale_actions"] = True  # only then: checkpoints without scaling load in code that predates it
    if args.denoiser == "mlp":
        model_kwargs["hidden"] = args.hidden
    model = (DiffusionNoisePredictor if args.denoiser == "mlp" else DiffusionUnetNoisePredictor)(**model_kwargs)
    model.obs_mean.copy_(torch.as_tensor(all_obs.mean(0)))
    model.obs_std.copy_(torch.as_tensor(all_obs.std(0)).clamp_min(1e-3))
    model.to(device)
    model.fit_action_scaling(sample_actions)
    sample_actions = model.to_unit(sample_actions)
    denoiser = model if args.compile == "off" else torch.compile(model, mode=args.compile)
    scheduler_config = dict(num_train_timesteps=args.diffusion_steps, beta_schedule="squaredcos_cap_v2", clip_sample=True, prediction_type="epsilon")
    scheduler = DDPMScheduler(**scheduler_config)
    optimiser = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-6)
    ema = EMAModel(parameters=model.parameters(), power=0.75, foreach=True) if args.ema else None
    run_dir = args.output_dir / (args.name or f"diffusion-{env_id}-{int(time.time())}")
    curve = LearningCurve(run_dir, ["iteration", "minutes", "loss", "success_once", "success_at_end", "return"])
    diffusion = dict(
        scheduler=scheduler_config, obs_horizon=args.obs_horizon, execute_horizon=args.execute_horizon, inference_steps=args.diffusion_steps
    )
    checkpoint = run_dir / "checkpoint.pt"
    best = BestCheckpoint(checkpoint)

    def save():
        if ema is not None:  # the averaged weights, the training ones put back after
            ema.store(model.parameters())
            ema.copy_to(model.parameters())
        save_checkpoint(checkpoint, "diffusion", model, model_kwargs, env_id, env_kwargs, obs_mode, control_mode, diffusion=diffusion)
        if ema is not None:
            ema.restore(model.parameters())

    scaling = " (actions scaled from their min-max range)" if model.scale_actions else ""
    print(f"{len(episodes)} demonstrations, {len(sample_obs)} samples of {env_id} {env_kwargs} on {device}{scaling}; training in {run_dir}")
    eval_seeds = range(args.eval_seed_start, args.eval_seed_start + args.eval_episodes)
    start = time.time()
    progress = tqdm(range(1, args.max_iterations + 1), desc="diffusion")
    for iteration in progress:
        model.train()
        batch = torch.as_tensor(rng.integers(0, len(sample_obs), args.batch_size), device=device)
        obs, actions = sample_obs[batch], sample_actions[batch]
        if args.obs_noise:
            obs = obs + args.obs_noise * model.obs_std * torch.randn_like(obs)
        noise = torch.randn_like(actions)
        steps = torch.randint(0, scheduler.config.num_train_timesteps, (len(actions),), device=device)
        noisy = scheduler.add_noise(actions, noise, steps)
        loss = torch.nn.functional.mse_loss(denoiser(noisy, steps, obs), noise)
        set_learning_rate(optimiser, args, iteration, (time.time() - start) / 60)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        if ema is not None:
            ema.step(model.parameters())
        minutes = (time.time() - start) / 60
        out_of_time = minutes >= args.minutes or iteration == args.max_iterations
        if iteration % 100 == 0:
            progress.set_postfix(loss=f"{loss.item():.4f}")
            curve.log(iteration=iteration, minutes=minutes, loss=loss.item())
        if iteration % args.eval_every == 0 or out_of_time:
            model.eval()
            save()
            if args.keep_snapshots:
                shutil.copyfile(checkpoint, run_dir / f"snapshot-{iteration}.pt")
            metrics = evaluate(CheckpointPolicy(str(checkpoint)), env_id, env_kwargs, eval_seeds) if args.eval_episodes else {}
            curve.log(iteration=iteration, minutes=minutes, loss=loss.item(), **{k.replace("episode_", ""): v for k, v in metrics.items()})
            progress.write(f"iteration {iteration}: {metrics}" + (" (best so far)" if metrics and best.update(metrics) else ""))
        if out_of_time:
            break
    curve.plot("iteration", ["loss", "success_once", "success_at_end", "return"], f"Diffusion policy on {env_id}")
    print(f"checkpoint: {checkpoint}" + (f", best in training evaluations: {best.path}" if best.score else ""))
    return checkpoint


if __name__ == "__main__":
    main(tyro.cli(Args))
