"""SAC from state, following ManiSkill's ``examples/baselines/sac`` (twin Q, automatic entropy tuning).

    python baselines/sac.py --env-id SampleCollection-v1 --env-kwargs '{"domain": "mars", "asset_source": "dataset"}'

Envs as in ``ppo.py`` (GPU-batched with CUDA, worker processes on a CPU). Writes ``runs/<name>/curve.csv``,
``curve.png`` and ``checkpoint.pt`` (the actor) for ``python -m mani_skill_space.eval --policy checkpoint:PATH``.
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import torch
import torch.nn as nn
import tyro
from tqdm import tqdm

from mani_skill_space.learning import LearningCurve, SquashedGaussianActor, VectorEnv, mlp, save_checkpoint


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
    log_every: int = 1_000
    output_dir: Path = Path("runs")
    name: Optional[str] = None
    seed: int = 0
    cuda: bool = True


class TwinQ(nn.Module):
    def __init__(self, state_dim: int, action_dim: int, hidden: int = 256):
        super().__init__()
        self.q1 = mlp([state_dim + action_dim, hidden, hidden, 1])
        self.q2 = mlp([state_dim + action_dim, hidden, hidden, 1])

    def forward(self, state, action):
        joint = torch.cat([state, action], dim=-1)
        return self.q1(joint).squeeze(-1), self.q2(joint).squeeze(-1)


def main(args: Args) -> Path:
    torch.manual_seed(args.seed)
    device = torch.device("cuda" if args.cuda and torch.cuda.is_available() else "cpu")
    env_kwargs = json.loads(args.env_kwargs)
    envs = VectorEnv(args.env_id, args.num_envs, env_kwargs, "state", args.control_mode, device)
    run_dir = args.output_dir / (args.name or f"sac-{args.env_id}-{int(time.time())}")
    curve = LearningCurve(run_dir, ["global_step", "minutes", "return", "success_once", "success_at_end", "episodes", "q_loss", "alpha"])
    obs = envs.reset(args.seed)
    space = envs.single_action_space
    state_dim, action_dim = obs["state"].shape[1], space.shape[0]
    model_kwargs = dict(state_dim=state_dim, action_dim=action_dim, action_low=space.low.tolist(), action_high=space.high.tolist())
    actor = SquashedGaussianActor(**model_kwargs).to(device)
    critic = TwinQ(state_dim, action_dim).to(device)
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
                q_loss = update(buffer, filled, args, actor, critic, target, log_alpha, target_entropy, actor_optimiser, critic_optimiser, alpha_optimiser)
        minutes = (time.time() - start) / 60
        out_of_time = args.minutes is not None and minutes >= args.minutes
        if global_step % args.log_every < n or out_of_time or global_step >= args.total_timesteps:
            row = dict(global_step=global_step, minutes=minutes, episodes=len(finished["returns"]), q_loss=q_loss.item(), alpha=log_alpha.exp().item())
            if finished["returns"]:
                row.update({"return": np.mean(finished["returns"]), "success_once": np.mean(finished["once"]), "success_at_end": np.mean(finished["end"])})
            curve.log(**row)
            finished = dict(returns=[], once=[], end=[])
            save_checkpoint(checkpoint, "sac", actor, model_kwargs, args.env_id, env_kwargs, "state", args.control_mode)
        if out_of_time:
            break
    progress.close()
    envs.close()
    save_checkpoint(checkpoint, "sac", actor, model_kwargs, args.env_id, env_kwargs, "state", args.control_mode)
    curve.plot("global_step", ["return", "success_once", "success_at_end"], f"SAC on {args.env_id}")
    print(f"checkpoint: {checkpoint}")
    return checkpoint


def update(buffer, filled, args, actor, critic, target, log_alpha, target_entropy, actor_optimiser, critic_optimiser, alpha_optimiser) -> torch.Tensor:
    index = torch.randint(0, filled, (args.batch_size,), device=log_alpha.device)
    state, action, reward = buffer["state"][index], buffer["action"][index], buffer["reward"][index]
    next_state, terminated = buffer["next_state"][index], buffer["terminated"][index]
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
