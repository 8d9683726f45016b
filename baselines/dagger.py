"""DAgger's data collection for Solar Panel Assembly: roll out a trained policy and label the states it visits
near a socket with the closed-loop push expert (``mani_skill_space.oracles.push_expert``).

    python baselines/dagger.py --checkpoint baselines/checkpoints/bc_solar_ee.pt --seed-start 20000 --episodes 40 \
        --output runs/dagger_solar/labels_0.h5
    python baselines/bc.py --demos <the demonstrations> --unsuccessful-demos --labelled-states runs/dagger_solar/labels_0.h5 ...

At every step the expert labels the state if a peg is in the hand with its end near the socket it should fill;
with probability ``--expert-share`` the expert's action is the one taken there (DAgger's beta, so that later
episodes see what comes after a push too), the policy's otherwise and everywhere else. Seeds start at 20000:
disjoint from the demonstrations' (0..), the training-time evaluations' (10000..) and the scoring suite's (5000..).

Writes ``<output>`` (``obs`` (N, d) and ``actions`` (N, a), the labelled states and the expert's actions; HDF5, no
code in it) and ``<output>.json`` (the env, the checkpoint and, per episode, its seed, labelled steps and stage).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import gymnasium as gym
import h5py
import numpy as np
import torch
import tyro
from tqdm import tqdm

import mani_skill_space  # noqa: F401  (registers the envs)
from mani_skill_space.learning import CheckpointPolicy
from mani_skill_space.oracles.push_expert import InsertionPushExpert
from mani_skill_space.rollout import episode_steps, evaluation_env_kwargs

SUPPORTED_ENVS = ("SolarPanelAssembly-v1",)


@dataclass
class Args:
    checkpoint: Path
    """The policy to roll out (a BC checkpoint trained in ``pd_ee_delta_pose`` on state observations)."""
    output: Path
    seed_start: int = 20_000
    episodes: int = 20
    expert_share: float = 0.5
    """Probability that a labelled step executes the expert's action instead of the policy's (DAgger's beta)."""
    seed: int = 0
    """Seeds the draws between the expert's and the policy's actions."""
    max_episode_steps: Optional[int] = None
    """Cut episodes short (the env's own limit by default), e.g. for a quick check."""


def collect(args: Args) -> dict:
    if not 0.0 <= args.expert_share <= 1.0:
        raise ValueError(f"--expert-share must be within [0, 1], got {args.expert_share}")
    policy = CheckpointPolicy(str(args.checkpoint))
    env_id, env_kwargs = policy.training_condition
    if env_id not in SUPPORTED_ENVS:
        raise ValueError(f"the push expert labels {', '.join(SUPPORTED_ENVS)}; {args.checkpoint} was trained on {env_id}")
    limit = {} if args.max_episode_steps is None else dict(max_episode_steps=args.max_episode_steps)
    env = gym.make(env_id, **evaluation_env_kwargs(env_kwargs, policy), **limit)
    expert = InsertionPushExpert(env.unwrapped)
    draws = np.random.default_rng(args.seed)
    observations, actions, episodes = [], [], []
    try:
        for seed in tqdm(range(args.seed_start, args.seed_start + args.episodes), desc="dagger"):
            obs, info = env.reset(seed=seed, options=dict(reconfigure=True))
            policy.reset(env, seed)
            labelled, stage = 0, 0
            for _ in range(episode_steps(env)):
                action = policy.act(obs)
                label = expert.label(info)
                if label is not None:
                    observations.append(obs[0].cpu().numpy())
                    actions.append(label)
                    labelled += 1
                    if draws.random() < args.expert_share:
                        action = torch.as_tensor(label)[None]
                obs, _, _, truncated, info = env.step(action)
                stage = max(stage, int(info["stage"]))
                if bool(truncated):
                    break
            episodes.append(dict(seed=seed, labelled_steps=labelled, stage=stage))
    finally:
        env.close()
    args.output.parent.mkdir(parents=True, exist_ok=True)
    with h5py.File(args.output, "w") as data:
        data["obs"] = np.asarray(observations, dtype=np.float32).reshape(len(observations), -1)
        data["actions"] = np.asarray(actions, dtype=np.float32).reshape(len(actions), -1)
    meta = dict(
        env_info=dict(env_id=env_id, env_kwargs=dict(env_kwargs, obs_mode=policy.obs_mode, control_mode=policy.control_mode)),
        checkpoint=str(args.checkpoint),
        expert_share=args.expert_share,
        episodes=episodes,
    )
    args.output.with_suffix(".json").write_text(json.dumps(meta, indent=1))
    print(f"{len(observations)} labelled states from {len(episodes)} episodes; mean stage {np.mean([e['stage'] for e in episodes]):.2f}")
    return meta


if __name__ == "__main__":
    collect(tyro.cli(Args))
