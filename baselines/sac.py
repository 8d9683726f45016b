"""SAC from state, following ManiSkill's ``examples/baselines/sac`` (twin Q, automatic entropy tuning).

    python baselines/sac.py --env-id SampleCollection-v1 --env-kwargs '{"domain": "mars", "asset_source": "dataset"}'

With ``--demos``, RLPD (Ball et al., 2023, as ManiSkill's ``examples/baselines/rlpd``): SAC with half of every
batch drawn from oracle demonstrations and LayerNorm in the critics, e.g. on the sparse reward

    python baselines/sac.py --env-id SampleCollection-v1 --env-kwargs '{"domain": "mars", "asset_source": "dataset"}' \
        --reward-mode sparse --demos demos/SampleCollection-v1/motionplanning/tubes.h5 --critic-layer-norm --gamma 0.9

or on the dense reward, from demonstrations replayed to record it (their files store success, not rewards):

    mani-skill-space replay --traj-path demos/SampleCollection-v1/motionplanning/tubes.h5 -o state --save-traj \
        --record-rewards --reward-mode normalized_dense
    python baselines/sac.py ... --demos demos/SampleCollection-v1/motionplanning/tubes.state.pd_ee_delta_pose.physx_cpu.h5 \
        --critic-layer-norm

Envs as in ``ppo.py`` (GPU-batched with CUDA, worker processes on a CPU). Writes ``runs/<name>/curve.csv``,
``curve.png`` and ``checkpoint.pt`` (the actor) for ``python -m mani_skill_space.eval --policy checkpoint:PATH``.
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Optional

import numpy as np
import torch
import torch.nn as nn
import tyro
from tqdm import tqdm

from mani_skill_space.learning import LearningCurve, SquashedGaussianActor, VectorEnv, load_demonstrations, mlp, save_checkpoint, task_of_demonstrations


@dataclass
class Args:
    env_id: str = "SampleCollection-v1"
    env_kwargs: str = "{}"
    """A JSON object of env kwargs (domain, asset_source, difficulty, ...)."""
    control_mode: str = "pd_ee_delta_pose"
    num_envs: int = 2
    total_timesteps: int = 100_000
    minutes: Optional[float] = None
    buffer_size: int = 1_000_000
    batch_size: int = 512
    learning_starts: int = 2_000
    """Random actions until this many env steps."""
    updates_per_step: float = 0.5
    """Gradient updates per env step (summed over envs)."""
    gamma: float = 0.8
    tau: float = 0.01
    lr: float = 3e-4
    reward_mode: Literal["normalized_dense", "dense", "sparse"] = "normalized_dense"
    """``sparse``: 1 on the steps the task is solved, else 0 (ManiSkill's sparse reward, what RLPD learns from)."""
    demos: Optional[Path] = None
    """RLPD: draw half of every batch from these demonstrations (a ManiSkill trajectory file with state
    observations, recorded on the same env, kwargs and control mode; its successful episodes), the other half
    from the agent's own interaction. With ``--reward-mode sparse`` their rewards are the file's per-step
    success; with a dense mode, the rewards the file records, which must be of that mode (``replay
    --record-rewards --reward-mode MODE``)."""
    num_demos: Optional[int] = None
    """Use only the first N successful demonstrations."""
    critic_layer_norm: bool = False
    """LayerNorm after each hidden layer of the critics (RLPD's guard against over-estimating the value of the
    actions that only the demonstrations take)."""
    log_every: int = 1_000
    output_dir: Path = Path("runs")
    name: Optional[str] = None
    seed: int = 0
    cuda: bool = True


class TwinQ(nn.Module):
    def __init__(self, state_dim: int, action_dim: int, hidden: int = 256, layer_norm: bool = False):
        super().__init__()
        sizes = [state_dim + action_dim, hidden, hidden, 1]
        self.q1 = _layer_normed_mlp(sizes) if layer_norm else mlp(sizes)
        self.q2 = _layer_normed_mlp(sizes) if layer_norm else mlp(sizes)

    def forward(self, state, action):
        joint = torch.cat([state, action], dim=-1)
        return self.q1(joint).squeeze(-1), self.q2(joint).squeeze(-1)


def _layer_normed_mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 2):
        layers += [nn.Linear(sizes[i], sizes[i + 1]), nn.LayerNorm(sizes[i + 1]), nn.ReLU()]
    return nn.Sequential(*layers, nn.Linear(sizes[-2], sizes[-1]))


def demonstration_transitions(args: Args, env_kwargs: dict, device: torch.device) -> dict[str, torch.Tensor]:
    """The successful episodes of ``args.demos`` as transitions with the reward being trained on: the sparse reward
    is the file's per-step success, a dense one the rewards the file recorded in that reward mode. The file must
    have been recorded on the env, kwargs and control mode being trained."""
    episodes, env_info = load_demonstrations(args.demos, limit=args.num_demos)
    recorded = task_of_demonstrations(env_info)
    wanted = (args.env_id, env_kwargs, "state", args.control_mode)
    if recorded != wanted:
        raise ValueError(f"{args.demos} holds demonstrations of {recorded} (env id, kwargs, obs mode, control mode), not {wanted}")
    if any("success" not in e or "terminated" not in e for e in episodes):
        raise ValueError(f"{args.demos} does not record per-step success and terminated flags")
    if args.reward_mode == "sparse":
        rewards = [e["success"] for e in episodes]
    else:
        recorded_mode = env_info["env_kwargs"].get("reward_mode")
        if recorded_mode != args.reward_mode or any("rewards" not in e for e in episodes):
            raise ValueError(
                f"--reward-mode {args.reward_mode} needs demonstrations that record that reward ({args.demos} records "
                f"{'no rewards' if any('rewards' not in e for e in episodes) else f'the {recorded_mode} reward'}): replay them with "
                f"`mani-skill-space replay --traj-path {args.demos} -o state --save-traj --record-rewards --reward-mode {args.reward_mode}`, or train with --reward-mode sparse"
            )
        rewards = [e["rewards"] for e in episodes]
    joined = lambda arrays: torch.as_tensor(np.concatenate(arrays), dtype=torch.float32, device=device)  # noqa: E731
    return dict(
        state=joined([e["obs"][:-1] for e in episodes]),
        action=joined([e["actions"] for e in episodes]),
        reward=joined(rewards),
        next_state=joined([e["obs"][1:] for e in episodes]),
        terminated=joined([e["terminated"] for e in episodes]),
    )


def main(args: Args) -> Path:
    torch.manual_seed(args.seed)
    device = torch.device("cuda" if args.cuda and torch.cuda.is_available() else "cpu")
    env_kwargs = json.loads(args.env_kwargs)
    demos = demonstration_transitions(args, env_kwargs, device) if args.demos is not None else None
    algorithm = "sac" if demos is None else "rlpd"
    envs = VectorEnv(args.env_id, args.num_envs, env_kwargs, "state", args.control_mode, device, reward_mode=args.reward_mode)
    run_dir = args.output_dir / (args.name or f"sac-{args.env_id}-{int(time.time())}")
    curve = LearningCurve(run_dir, ["global_step", "minutes", "return", "success_once", "success_at_end", "episodes", "q_loss", "alpha"])
    obs = envs.reset(args.seed)
    space = envs.single_action_space
    state_dim, action_dim = obs["state"].shape[1], space.shape[0]
    model_kwargs = dict(state_dim=state_dim, action_dim=action_dim, action_low=space.low.tolist(), action_high=space.high.tolist())
    actor = SquashedGaussianActor(**model_kwargs).to(device)
    critic = TwinQ(state_dim, action_dim, layer_norm=args.critic_layer_norm).to(device)
    target = copy.deepcopy(critic)
    log_alpha = torch.zeros(1, requires_grad=True, device=device)
    target_entropy = -float(action_dim)
    actor_optimiser = torch.optim.Adam(actor.parameters(), lr=args.lr)
    critic_optimiser = torch.optim.Adam(critic.parameters(), lr=args.lr)
    alpha_optimiser = torch.optim.Adam([log_alpha], lr=args.lr)

    size = args.buffer_size
    buffer = dict(
        state=torch.zeros((size, state_dim), device=device),
        action=torch.zeros((size, action_dim), device=device),
        reward=torch.zeros(size, device=device),
        next_state=torch.zeros((size, state_dim), device=device),
        terminated=torch.zeros(size, device=device),
    )
    filled, cursor = 0, 0
    n = args.num_envs
    episode_return = torch.zeros(n, device=device)
    episode_success = torch.zeros(n, dtype=torch.bool, device=device)
    finished = dict(returns=[], once=[], end=[])
    start, global_step, q_loss, pending_updates = time.time(), 0, torch.tensor(0.0), 0.0
    checkpoint = run_dir / "checkpoint.pt"
    progress = tqdm(total=args.total_timesteps, desc="sac")
    while global_step < args.total_timesteps:
        if global_step < args.learning_starts:
            action = torch.as_tensor(np.stack([space.sample() for _ in range(n)]), device=device)
        else:
            with torch.no_grad():
                action, _ = actor.sample(obs)
        next_obs, reward, terminated, truncated, final_obs, success = envs.step(action)
        done = terminated | truncated
        real_next = next_obs["state"].clone()
        if final_obs is not None:
            real_next[done] = final_obs["state"][done]
        index = (cursor + torch.arange(n, device=device)) % size
        buffer["state"][index], buffer["action"][index], buffer["reward"][index] = obs["state"], action, reward
        buffer["next_state"][index], buffer["terminated"][index] = real_next, terminated.float()
        cursor, filled = (cursor + n) % size, min(filled + n, size)
        episode_return += reward
        episode_success |= success
        for i in torch.nonzero(done).flatten().tolist():
            finished["returns"].append(episode_return[i].item())
            finished["once"].append(episode_success[i].item())
            finished["end"].append(success[i].item())
        episode_return[done], episode_success[done] = 0.0, False
        obs = next_obs
        global_step += n
        progress.update(n)

        if global_step >= args.learning_starts:
            pending_updates += n * args.updates_per_step
            while pending_updates >= 1:
                pending_updates -= 1
                batch = sample_batch(buffer, filled, demos, args.batch_size)
                q_loss = update(batch, args, actor, critic, target, log_alpha, target_entropy, actor_optimiser, critic_optimiser, alpha_optimiser)
        minutes = (time.time() - start) / 60
        out_of_time = args.minutes is not None and minutes >= args.minutes
        if global_step % args.log_every < n or out_of_time or global_step >= args.total_timesteps:
            row = dict(global_step=global_step, minutes=minutes, episodes=len(finished["returns"]), q_loss=q_loss.item(), alpha=log_alpha.exp().item())
            if finished["returns"]:
                row.update({"return": np.mean(finished["returns"]), "success_once": np.mean(finished["once"]), "success_at_end": np.mean(finished["end"])})
            curve.log(**row)
            finished = dict(returns=[], once=[], end=[])
            save_checkpoint(checkpoint, algorithm, actor, model_kwargs, args.env_id, env_kwargs, "state", args.control_mode)
        if out_of_time:
            break
    progress.close()
    envs.close()
    save_checkpoint(checkpoint, algorithm, actor, model_kwargs, args.env_id, env_kwargs, "state", args.control_mode)
    curve.plot("global_step", ["return", "success_once", "success_at_end"], f"{algorithm.upper()} on {args.env_id}")
    print(f"checkpoint: {checkpoint}")
    return checkpoint


def sample_batch(buffer: dict, filled: int, demos: Optional[dict], batch_size: int) -> dict[str, torch.Tensor]:
    """``batch_size`` transitions from the first ``filled`` of the replay buffer, or, with demonstrations, half
    from them and half from the buffer (RLPD's symmetric sampling)."""
    own = batch_size if demos is None else batch_size - batch_size // 2
    device = buffer["state"].device
    index = torch.randint(0, filled, (own,), device=device)
    batch = {key: values[index] for key, values in buffer.items()}
    if demos is not None:
        demo_index = torch.randint(0, len(demos["state"]), (batch_size - own,), device=device)
        batch = {key: torch.cat([values, demos[key][demo_index]]) for key, values in batch.items()}
    return batch


def update(batch, args, actor, critic, target, log_alpha, target_entropy, actor_optimiser, critic_optimiser, alpha_optimiser) -> torch.Tensor:
    state, action, reward, next_state, terminated = (batch[key] for key in ("state", "action", "reward", "next_state", "terminated"))
    alpha = log_alpha.exp().detach()
    with torch.no_grad():
        next_action, next_logprob = actor.sample({"state": next_state})
        next_q = torch.min(*target(next_state, next_action)) - alpha * next_logprob
        goal = reward + args.gamma * (1.0 - terminated) * next_q
    q1, q2 = critic(state, action)
    q_loss = ((q1 - goal) ** 2).mean() + ((q2 - goal) ** 2).mean()
    critic_optimiser.zero_grad()
    q_loss.backward()
    critic_optimiser.step()

    new_action, logprob = actor.sample({"state": state})
    actor_loss = (alpha * logprob - torch.min(*critic(state, new_action))).mean()
    actor_optimiser.zero_grad()
    actor_loss.backward()
    actor_optimiser.step()
    alpha_loss = -(log_alpha * (logprob.detach() + target_entropy)).mean()
    alpha_optimiser.zero_grad()
    alpha_loss.backward()
    alpha_optimiser.step()
    with torch.no_grad():
        for parameter, target_parameter in zip(critic.parameters(), target.parameters()):
            target_parameter.mul_(1 - args.tau).add_(args.tau * parameter)
    return q_loss.detach()


if __name__ == "__main__":
    main(tyro.cli(Args))
