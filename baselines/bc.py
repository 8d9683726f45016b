"""Behaviour cloning from oracle demonstrations (state observations), in the style of ManiSkill's baselines.

Demonstrations: generate with the oracle and convert them to the control mode to learn, e.g.

    python -m mani_skill_space.demos -e SampleCollection-v1 -n 200 -j 2 --env-kwargs '{"domain": "mars", "asset_source": "dataset"}'
    python -m mani_skill_space.replay --traj-path demos/SampleCollection-v1/motionplanning/<name>.h5 \
        -c pd_ee_delta_pose -o state --save-traj --num-procs 2
    python baselines/bc.py --demos demos/SampleCollection-v1/motionplanning/<name>.state.pd_ee_delta_pose.physx_cpu.h5

Writes ``runs/<name>/curve.csv`` and ``curve.png`` (loss, and success_once / success_at_end / return of
periodic evaluations on seeds disjoint from the demonstrations), ``runs/<name>/checkpoint.pt`` (the last) and
``runs/<name>/best.pt`` (the best in those evaluations; BC overfits its demonstrations as it trains on), which
the evaluation CLI scores with ``--policy checkpoint:runs/<name>/best.pt``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import torch
import tyro
from tqdm import tqdm

from mani_skill_space.learning import (
    BehaviourCloningPolicy,
    BestCheckpoint,
    CheckpointPolicy,
    LearningCurve,
    LrSchedule,
    load_checkpoint,
    load_demonstrations,
    load_labelled_states,
    load_model,
    observed_dims,
    save_checkpoint,
    set_learning_rate,
    state_layout,
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
    labelled_states: tuple[Path, ...] = ()
    """DAgger: states an expert labelled on a policy's own rollouts (``baselines/dagger.py``), learned from
    together with the demonstrations (same env, obs and control mode)."""
    labelled_share: Optional[float] = None
    """Share of every batch drawn from ``--labelled-states`` (None: uniformly from all transitions)."""
    observe: tuple[str, ...] = ()
    """Learn from these entries of the state observation only (names as ``agent/qpos``, ``extra/tcp_pos``; every
    entry by default), e.g. Solar Panel Assembly's next peg's slots without the four pegs' own. The checkpoint keeps
    the columns, so the evaluation CLI feeds the policy the same."""
    init_checkpoint: Optional[Path] = None
    """Start from this BC checkpoint (its network and observation normalisation) instead of from scratch, e.g. the
    policy whose rollouts were labelled."""
    minutes: float = 20.0
    """Wall-clock training budget (evaluations included)."""
    max_iterations: int = 100_000
    batch_size: int = 512
    lr: float = 3e-4
    hidden: int = 512
    obs_noise: float = 0.05
    """Gaussian noise (in units of each observation's standard deviation) added to training observations, so
    that the policy has seen states a little off the demonstrations (closed-loop errors compound otherwise)."""
    lr_schedule: LrSchedule = "constant"
    """``cosine`` decays the learning rate to zero over the training budget (``--minutes`` or
    ``--max-iterations``, whichever ends first), as ManiSkill's diffusion policy baseline does: the last
    iterations refine rather than jump, which a millimetre-precise task (the peg's 1 mm clearance) needs."""
    balance_action_loss: bool = False
    """Weigh each action dimension's squared error by the inverse of its variance in the demonstrations: the
    gripper's +-1 otherwise outweighs the small end-effector translations a precise insertion is made of."""
    eval_every: int = 4000
    """Evaluate every N iterations (and at the end)."""
    eval_episodes: int = 20
    eval_seed_start: int = 10_000
    """Evaluation seeds start here: disjoint from the demonstrations' (0..)."""
    output_dir: Path = Path("runs")
    name: Optional[str] = None
    seed: int = 0
    device: str = "auto"
    """``auto``: CUDA where torch finds it, else the CPU. Checkpoints are saved with CPU tensors either way."""


def main(args: Args) -> Path:
    torch.manual_seed(args.seed)
    episodes, env_info = load_demonstrations(args.demos, success_only=not args.unsuccessful_demos, limit=args.num_demos)
    env_id, env_kwargs, obs_mode, control_mode = task_of_demonstrations(env_info)
    obs = torch.as_tensor(np.concatenate([e["obs"][:-1] for e in episodes]))
    actions = torch.as_tensor(np.concatenate([e["actions"] for e in episodes]))
    labelled_obs, labelled_actions = load_labelled(args, (env_id, env_kwargs, obs_mode, control_mode), obs.shape[1], actions.shape[1])
    draw = batch_sampler(len(obs), len(labelled_obs), args.labelled_share, args.batch_size)
    obs, actions = torch.cat([obs, labelled_obs]), torch.cat([actions, labelled_actions])
    run_dir = args.output_dir / (args.name or f"bc-{env_id}-{int(time.time())}")
    if args.init_checkpoint is not None:
        if args.observe:
            raise ValueError("--observe cannot be combined with --init-checkpoint (the checkpoint's network already fixes what it observes); give one of them")
        model, model_kwargs = initial_model(args.init_checkpoint, env_id, obs.shape[1])
    else:
        model_kwargs = dict(state_dim=obs.shape[1], action_dim=actions.shape[1], hidden=args.hidden)
        if args.observe:
            model_kwargs["observed"] = observed_dims(observation_layout(env_id, env_kwargs, obs_mode, control_mode, obs.shape[1]), args.observe)
        model = BehaviourCloningPolicy(**model_kwargs)
        model.obs_mean.copy_(obs.mean(0))
        model.obs_std.copy_(obs.std(0).clamp_min(1e-3))
    device = torch.device(("cuda" if torch.cuda.is_available() else "cpu") if args.device == "auto" else args.device)
    model.to(device)
    optimiser = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=1e-4)
    loss_weights = (action_loss_weights(actions) if args.balance_action_loss else torch.ones(actions.shape[1])).to(device)
    curve = LearningCurve(run_dir, ["iteration", "minutes", "loss", "success_once", "success_at_end", "return"])
    obs, actions = obs.to(device), actions.to(device)
    print(f"{len(episodes)} demonstrations and {len(labelled_obs)} labelled states, {len(obs)} transitions of {env_id} {env_kwargs} on {device}; training in {run_dir}")

    checkpoint = run_dir / "checkpoint.pt"
    best = BestCheckpoint(checkpoint)
    start = time.time()
    save = lambda: save_checkpoint(checkpoint, "bc", model, model_kwargs, env_id, env_kwargs, obs_mode, control_mode)  # noqa: E731
    eval_seeds = range(args.eval_seed_start, args.eval_seed_start + args.eval_episodes)
    progress = tqdm(range(1, args.max_iterations + 1), desc="bc")
    for iteration in progress:
        batch = draw().to(device)
        inputs = obs[batch] + args.obs_noise * model.obs_std * torch.randn_like(obs[batch])
        loss = ((model(inputs) - actions[batch]).pow(2) * loss_weights).mean()
        set_learning_rate(optimiser, args, iteration, (time.time() - start) / 60)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        minutes = (time.time() - start) / 60
        out_of_time = minutes >= args.minutes or iteration == args.max_iterations
        if iteration % 100 == 0:
            progress.set_postfix(loss=f"{loss.item():.4f}")
            curve.log(iteration=iteration, minutes=minutes, loss=loss.item())
        if iteration % args.eval_every == 0 or out_of_time:
            save()
            metrics = evaluate(CheckpointPolicy(str(checkpoint)), env_id, env_kwargs, eval_seeds) if args.eval_episodes else {}
            curve.log(iteration=iteration, minutes=minutes, loss=loss.item(), **{k.replace("episode_", ""): v for k, v in metrics.items()})
            progress.write(f"iteration {iteration}: {metrics}" + (" (best so far)" if metrics and best.update(metrics) else ""))
        if out_of_time:
            break
    curve.plot("iteration", ["loss", "success_once", "success_at_end", "return"], f"BC on {env_id}")
    print(f"checkpoint: {checkpoint}" + (f", best in training evaluations: {best.path}" if best.score else ""))
    return checkpoint


def evaluate(policy, env_id: str, env_kwargs: dict, seeds) -> dict[str, float]:
    from mani_skill_space.rollout import evaluate_policy  # the simulator only where training evaluates

    return evaluate_policy(policy, env_id, env_kwargs, seeds)


def observation_layout(env_id: str, env_kwargs: dict, obs_mode: str, control_mode: str, state_dim: int) -> dict[str, slice]:
    """The demonstrations' state vector's layout (``state_layout``), read off the env they were recorded in."""
    import gymnasium as gym

    import mani_skill_space  # noqa: F401  (registers the envs)

    if obs_mode != "state":
        raise ValueError(f"--observe selects state observation entries; the demonstrations are in obs mode {obs_mode!r}")
    env = gym.make(env_id, obs_mode="state_dict", control_mode=control_mode, **env_kwargs)
    try:
        obs, _ = env.reset(seed=0)
        layout = state_layout(obs)
    finally:
        env.close()
    width = max(s.stop for s in layout.values())
    if width != state_dim:
        raise ValueError(f"{env_id} gives {width} state observations and the demonstrations {state_dim}: they were recorded with another version of its observations")
    return layout


def load_labelled(args: Args, task: tuple, state_dim: int, action_dim: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``--labelled-states`` files' states and actions, checked to be of the demonstrations' task."""
    observations, actions = [torch.zeros((0, state_dim))], [torch.zeros((0, action_dim))]
    for path in args.labelled_states:
        obs, labels, env_info = load_labelled_states(path)
        if task_of_demonstrations(env_info) != task:
            raise ValueError(f"{path} was labelled on {task_of_demonstrations(env_info)}, the demonstrations are of {task}")
        if obs.shape[1] != state_dim or labels.shape[1] != action_dim:
            raise ValueError(f"{path} has {obs.shape[1]} state and {labels.shape[1]} action dimensions, the demonstrations {state_dim} and {action_dim}")
        observations.append(torch.as_tensor(obs))
        actions.append(torch.as_tensor(labels))
    return torch.cat(observations), torch.cat(actions)


def batch_sampler(demonstrated: int, labelled: int, labelled_share: Optional[float], batch_size: int):
    """Indices into the demonstrations' transitions followed by the labelled states: ``labelled_share`` of each
    batch from the latter, or uniformly from both (None)."""
    if labelled_share is None:
        return lambda: torch.randint(0, demonstrated + labelled, (batch_size,))
    if not 0.0 < labelled_share < 1.0:
        raise ValueError(f"--labelled-share must be within (0, 1), got {labelled_share}")
    if not labelled:
        raise ValueError("--labelled-share needs --labelled-states to draw from")
    from_labelled = round(batch_size * labelled_share)
    return lambda: torch.cat([torch.randint(0, demonstrated, (batch_size - from_labelled,)), demonstrated + torch.randint(0, labelled, (from_labelled,))])


def initial_model(path: Path, env_id: str, state_dim: int) -> tuple[BehaviourCloningPolicy, dict]:
    """``--init-checkpoint``'s network (trainable), checked to be a BC policy of this env and state size."""
    checkpoint = load_checkpoint(path)
    if checkpoint["algorithm"] != "bc" or checkpoint["env_id"] != env_id:
        raise ValueError(f"--init-checkpoint {path} is {checkpoint['algorithm']} on {checkpoint['env_id']}; expected bc on {env_id}")
    if checkpoint["model_kwargs"]["state_dim"] != state_dim:
        raise ValueError(f"--init-checkpoint {path} takes {checkpoint['model_kwargs']['state_dim']} state dimensions, the demonstrations have {state_dim}")
    return load_model(checkpoint).train(), dict(checkpoint["model_kwargs"])


def action_loss_weights(actions: torch.Tensor) -> torch.Tensor:
    """Per-dimension weights 1 / variance (a dimension that never varies weighs as one of variance 1e-4),
    scaled to average 1 so that the loss keeps the magnitude ``--lr`` was tuned for."""
    weights = 1.0 / actions.var(0).clamp_min(1e-4)
    return weights / weights.mean()


if __name__ == "__main__":
    main(tyro.cli(Args))
