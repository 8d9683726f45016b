"""PPO from state or from RGB-D (both cameras, 64x64), following ManiSkill's ``examples/baselines/ppo``.

    python baselines/ppo.py --env-id SampleCollection-v1 --env-kwargs '{"domain": "mars", "asset_source": "dataset"}'
    python baselines/ppo.py --env-id PegInHoleAssembly-v1 --obs-mode rgbd --num-envs 4

With CUDA the envs run GPU-batched (``num_envs`` sub-scenes in one ManiSkill env); on a CPU each env runs in
its own worker process (``gymnasium.vector.AsyncVectorEnv``). Writes ``runs/<name>/curve.csv`` and
``curve.png`` (mean return, success_once and success_at_end of the episodes finished in each rollout) and
``runs/<name>/checkpoint.pt`` for ``python -m mani_skill_space.eval --policy checkpoint:PATH``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np
import torch
import tyro
from tqdm import tqdm

from mani_skill_space.learning import GaussianActorCritic, LearningCurve, VectorEnv, save_checkpoint


@dataclass
class Args:
    env_id: str = "SampleCollection-v1"
    env_kwargs: str = "{}"
    """A JSON object of env kwargs (domain, asset_source, difficulty, ...)."""
    obs_mode: str = "state"
    """state or rgbd"""
    control_mode: str = "pd_ee_delta_pose"
    num_envs: int = 2
    """Parallel envs (GPU sub-scenes, or CPU worker processes)."""
    num_steps: int = 50
    """Steps per env per rollout."""
    total_timesteps: int = 100_000
    minutes: Optional[float] = None
    """Stop after this many minutes of training (whichever comes first)."""
    gamma: float = 0.8
    gae_lambda: float = 0.9
    learning_rate: float = 3e-4
    update_epochs: int = 4
    num_minibatches: int = 4
    clip_coef: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    target_kl: float = 0.1
    output_dir: Path = Path("runs")
    name: Optional[str] = None
    seed: int = 0
    cuda: bool = True


def main(args: Args) -> Path:
    torch.manual_seed(args.seed)
    device = torch.device("cuda" if args.cuda and torch.cuda.is_available() else "cpu")
    env_kwargs = json.loads(args.env_kwargs)
    envs = VectorEnv(args.env_id, args.num_envs, env_kwargs, args.obs_mode, args.control_mode, device)
    run_dir = args.output_dir / (args.name or f"ppo-{args.env_id}-{args.obs_mode}-{int(time.time())}")
    curve = LearningCurve(run_dir, ["global_step", "minutes", "return", "success_once", "success_at_end", "episodes", "value_loss", "policy_loss"])
    obs = envs.reset(args.seed)
    action_space = envs.single_action_space
    low, high = torch.as_tensor(action_space.low, device=device), torch.as_tensor(action_space.high, device=device)
    image_channels = obs["rgb"].shape[-1] + obs["depth"].shape[-1] if "rgb" in obs else 0
    model_kwargs = dict(state_dim=obs["state"].shape[1], action_dim=action_space.shape[0], image_channels=image_channels)
    agent = GaussianActorCritic(**model_kwargs).to(device)
    optimiser = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)

    n, steps = args.num_envs, args.num_steps
    batch_size = n * steps
    minibatch = max(1, batch_size // args.num_minibatches)
    storage_obs = {k: torch.zeros((steps, *v.shape), dtype=v.dtype, device=device) for k, v in obs.items()}
    actions = torch.zeros((steps, n, action_space.shape[0]), device=device)
    logprobs, rewards, values, dones, bootstrap = (torch.zeros((steps, n), device=device) for _ in range(5))
    episode_return = torch.zeros(n, device=device)
    episode_success = torch.zeros(n, dtype=torch.bool, device=device)
    start, global_step = time.time(), 0
    iterations = max(1, args.total_timesteps // batch_size)
    checkpoint = run_dir / "checkpoint.pt"
    for iteration in tqdm(range(1, iterations + 1), desc="ppo"):
        finished_returns, finished_once, finished_end = [], [], []
        for step in range(steps):
            global_step += n
            for k in obs:
                storage_obs[k][step] = obs[k]
            with torch.no_grad():
                distribution, value = agent.distribution(obs)
                action = distribution.sample()
                logprobs[step] = distribution.log_prob(action).sum(-1)
            values[step], actions[step] = value, action
            obs, reward, terminated, truncated, final_obs, success = envs.step(torch.clamp(action, low, high))
            done = terminated | truncated
            rewards[step], dones[step] = reward, done.float()
            episode_return += reward
            episode_success |= success
            if truncated.any() and final_obs is not None:  # a time limit, not a real end: bootstrap from the value
                with torch.no_grad():
                    final_value = agent.value(final_obs)
                bootstrap[step] = torch.where(truncated & ~terminated, final_value, torch.zeros_like(final_value))
            else:
                bootstrap[step] = 0.0
            for i in torch.nonzero(done).flatten().tolist():
                finished_returns.append(episode_return[i].item())
                finished_once.append(episode_success[i].item())
                finished_end.append(success[i].item())
            episode_return[done], episode_success[done] = 0.0, False

        with torch.no_grad():
            next_value = agent.value(obs)
            advantages = torch.zeros_like(rewards)
            last = torch.zeros(n, device=device)
            for t in reversed(range(steps)):
                following = next_value if t == steps - 1 else values[t + 1]
                not_done = 1.0 - dones[t]
                delta = rewards[t] + args.gamma * (following * not_done + bootstrap[t]) - values[t]
                last = delta + args.gamma * args.gae_lambda * not_done * last
                advantages[t] = last
            returns = advantages + values

        flat_obs = {k: v.reshape(batch_size, *v.shape[2:]) for k, v in storage_obs.items()}
        flat = dict(actions=actions.reshape(batch_size, -1), logprobs=logprobs.reshape(-1), advantages=advantages.reshape(-1), returns=returns.reshape(-1))
        value_loss = policy_loss = torch.tensor(0.0)
        for _ in range(args.update_epochs):
            order = torch.randperm(batch_size, device=device)
            approx_kl = torch.tensor(0.0)
            for begin in range(0, batch_size, minibatch):
                index = order[begin : begin + minibatch]
                distribution, value = agent.distribution({k: v[index] for k, v in flat_obs.items()})
                new_logprob = distribution.log_prob(flat["actions"][index]).sum(-1)
                ratio = (new_logprob - flat["logprobs"][index]).exp()
                approx_kl = ((ratio - 1) - (new_logprob - flat["logprobs"][index])).mean()
                advantage = flat["advantages"][index]
                advantage = (advantage - advantage.mean()) / (advantage.std() + 1e-8)
                policy_loss = torch.max(-advantage * ratio, -advantage * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)).mean()
                value_loss = 0.5 * ((value - flat["returns"][index]) ** 2).mean()
                loss = policy_loss + args.vf_coef * value_loss - args.ent_coef * distribution.entropy().sum(-1).mean()
                optimiser.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
                optimiser.step()
            if args.target_kl is not None and approx_kl > args.target_kl:
                break

        minutes = (time.time() - start) / 60
        row = dict(global_step=global_step, minutes=minutes, episodes=len(finished_returns), value_loss=value_loss.item(), policy_loss=policy_loss.item())
        if finished_returns:
            row.update({"return": np.mean(finished_returns), "success_once": np.mean(finished_once), "success_at_end": np.mean(finished_end)})
        curve.log(**row)
        save_checkpoint(checkpoint, "ppo", agent, model_kwargs, args.env_id, env_kwargs, args.obs_mode, args.control_mode)
        if args.minutes is not None and minutes >= args.minutes:
            break
    envs.close()
    curve.plot("global_step", ["return", "success_once", "success_at_end"], f"PPO ({args.obs_mode}) on {args.env_id}")
    print(f"checkpoint: {checkpoint}")
    return checkpoint


if __name__ == "__main__":
    main(tyro.cli(Args))
