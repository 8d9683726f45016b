"""Roll out every env in each of its domains and asset sources; write a picture grid and a video per domain.

    python -m mani_skill_space.showcase --output-dir outputs/showcase

The picture (``first_frames.png``) has one row per env x domain and one column per asset source, each the
render camera's first frame after reset. Each video shows the asset sources side by side under a random
policy (a fixed seed, so the same command gives the same pictures).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
import tyro
from PIL import Image, ImageDraw
from tqdm import tqdm

import mani_skill_space
from mani_skill_space.envs import task_class


@dataclass
class Args:
    output_dir: Path = Path("outputs/showcase")
    env_ids: tuple[str, ...] = mani_skill_space.ENV_IDS
    steps: int = 40
    """Control steps per video."""
    seed: int = 0
    image_size: int = 256
    fps: int = 20


def rollout_frames(env_id: str, domain: str, asset_source: str, args: Args) -> list[np.ndarray]:
    env = gym.make(
        env_id,
        domain=domain,
        asset_source=asset_source,
        obs_mode="state",
        render_mode="rgb_array",
        human_render_camera_configs=dict(width=args.image_size, height=args.image_size),
    )
    try:
        env.reset(seed=args.seed)
        env.action_space.seed(args.seed)
        frames = [_frame(env)]
        for _ in range(args.steps):
            env.step(env.action_space.sample())
            frames.append(_frame(env))
        return frames
    finally:
        env.close()


def _frame(env) -> np.ndarray:
    return np.asarray(env.render()[0].cpu().numpy(), dtype=np.uint8)


def labelled(image: np.ndarray, text: str) -> np.ndarray:
    picture = Image.fromarray(image)
    draw = ImageDraw.Draw(picture)
    draw.rectangle([0, 0, 8 + 6 * len(text), 14], fill=(0, 0, 0))
    draw.text((4, 2), text, fill=(255, 255, 255))
    return np.asarray(picture)


def main(args: Args) -> None:
    args.output_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    jobs = [(env_id, domain) for env_id in args.env_ids for domain in task_class(env_id).SUPPORTED_DOMAINS]
    for env_id, domain in tqdm(jobs, desc="showcase"):
        sources = task_class(env_id).SUPPORTED_ASSET_SOURCES
        rollouts = {source: rollout_frames(env_id, domain, source, args) for source in sources}
        rows.append(np.concatenate([labelled(rollouts[s][0], f"{env_id} {domain} {s}") for s in sources], axis=1))
        video = args.output_dir / f"{env_id}_{domain}.mp4"
        side_by_side = [np.concatenate(frames, axis=1) for frames in zip(*rollouts.values())]
        imageio.mimsave(video, side_by_side, fps=args.fps)
        print(f"video: {video}")
    width = max(r.shape[1] for r in rows)
    grid = np.concatenate([np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0))) for r in rows], axis=0)
    picture = args.output_dir / "first_frames.png"
    Image.fromarray(grid).save(picture)
    print(f"picture: {picture}")


if __name__ == "__main__":
    main(tyro.cli(Args))
