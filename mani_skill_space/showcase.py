"""Roll out every env in each of its domains and asset sources; write a picture grid and a video per domain.

    mani-skill-space showcase --output-dir outputs/showcase
    python -m mani_skill_space.showcase --output-dir outputs/showcase

The picture (``first_frames.png``) has one row per env x domain and one column per asset source, each the
render camera's first frame after reset. Each video shows the asset sources side by side under a random
policy (a fixed seed, so the same command gives the same pictures).

``procedural_variety()`` draws many procedural assets side by side (rocks, peg and hole pairs, debris, solar
panel sets), rendered offscreen with their own materials; ``assets/readme/make_pictures.py`` makes the README's
pictures with both.

The env ids and sizes are checked before anything is rendered; a bad one is one line on stderr and exit status 2
(``--debug`` shows the traceback; see ``mani_skill_space.cli_support``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Sequence

import gymnasium as gym
import imageio.v2 as imageio
import numpy as np
import sapien
from PIL import Image, ImageDraw
from tqdm import tqdm

import mani_skill_space
from mani_skill_space.cli_support import check_at_least, checking_inputs, run_cli, tyro_parser
from mani_skill_space.envs import task_class
from mani_skill_space.envs.building import render_shape
from mani_skill_space.procgen.asset import Asset, VisualPart, box_mesh, look_at
from mani_skill_space.procgen.debris import make_debris
from mani_skill_space.procgen.peg_hole import make_peg_hole_pair
from mani_skill_space.procgen.rock import make_rock
from mani_skill_space.procgen.solar_panel import SEAT_HEIGHT, make_panel, make_socket_base, make_solar_layout, make_solar_pegs

VARIETY_FLOOR_COLOR = (0.2, 0.21, 0.24, 1.0)
"""A dark grey floor under the assets of the variety picture (their shadows on it show their shapes)."""
VARIETY_CAMERA_ELEVATION = np.radians(62.0)
VARIETY_CAMERA_FOVY = np.radians(30.0)
PANEL_LIFT = 0.12
"""How far (m) above its seat the variety picture holds each solar panel, so that the pegs in the sockets show."""

Placed = tuple[Asset, np.ndarray]
"""An asset and its 4x4 pose in a picture."""


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


def procedural_variety(count: int = 16, solar_count: int = 4, seed: int = 0, panel_size: int = 320) -> np.ndarray:
    """A picture of the procedural assets, one square panel per kind side by side, at true scale within a panel:
    ``count`` rocks (lunar and Martian in turn), ``count`` peg and hole pairs (each peg standing by its module),
    ``count`` debris pieces and ``solar_count`` solar panel sets (pegs in their sockets, the panel held above
    them), from seeds ``seed`` on."""
    kinds = [
        (f"{count} rocks", [_rock_kit(seed + i) for i in range(count)]),
        (f"{count} peg and hole pairs", [_peg_hole_kit(seed + i) for i in range(count)]),
        (f"{count} debris", [_debris_kit(seed + i) for i in range(count)]),
        (f"{solar_count} solar panel sets", [_solar_kit(seed + i) for i in range(solar_count)]),
    ]
    return np.concatenate([labelled(_render_kits(kits, panel_size), text) for text, kits in kinds], axis=1)


def _rock_kit(seed: int) -> list[Placed]:
    return [_on_floor(make_rock(seed, "lunar" if seed % 2 == 0 else "martian"))]


def _debris_kit(seed: int) -> list[Placed]:
    return [_on_floor(make_debris(seed))]


def _peg_hole_kit(seed: int) -> list[Placed]:
    peg, module = make_peg_hole_pair(seed)
    module_half_width = module.visual_mesh.extents[1] / 2
    return [_on_floor(module), _on_floor(peg, (0.0, -module_half_width - 0.035))]


def _solar_kit(seed: int) -> list[Placed]:
    layout = make_solar_layout(seed)
    pegs = make_solar_pegs(layout, seed)
    placed = [_on_floor(make_socket_base(layout))]
    placed += [_on_floor(peg, xy, SEAT_HEIGHT - length) for peg, xy, length in zip(pegs, layout.socket_xy, layout.peg_lengths)]
    placed.append(_on_floor(make_panel(layout), height=SEAT_HEIGHT + PANEL_LIFT))
    return placed


def _on_floor(asset: Asset, xy=(0.0, 0.0), height: float = 0.0) -> Placed:
    """The pose that puts the asset's bounding box centre over ``xy`` and its bottom at ``height``."""
    low, high = asset.visual_mesh.bounds
    pose = np.eye(4)
    pose[:3, 3] = [xy[0] - (low[0] + high[0]) / 2, xy[1] - (low[1] + high[1]) / 2, height - low[2]]
    return asset, pose


def _render_kits(kits: list[list[Placed]], size: int) -> np.ndarray:
    """Lay the kits out on a grid (row by row, the first at the back left) and render them from the front, above."""
    bounds = [_kit_bounds(kit) for kit in kits]
    largest = np.max([high[:2] - low[:2] for low, high in bounds], axis=0)
    cell = largest + 0.3 * largest.max()
    columns = int(np.ceil(np.sqrt(len(kits))))
    rows = int(np.ceil(len(kits) / columns))
    span = cell * [rows, columns]
    scene = sapien.Scene()
    scene.set_ambient_light([0.35, 0.35, 0.35])
    scene.add_directional_light([0.4, 0.6, -1.0], [2.2, 2.2, 2.1], shadow=True, shadow_scale=float(span.max()), shadow_map_size=2048)
    for index, (kit, (low, high)) in enumerate(zip(kits, bounds)):
        row, column = divmod(index, columns)
        centre = np.array([(rows - 1) / 2 - row, (columns - 1) / 2 - column]) * cell - (low[:2] + high[:2]) / 2
        for asset, pose in kit:
            _add_visual(scene, asset, pose, np.array([*centre, 0.0]))
    extent = 2 * float(span.max())
    floor = Asset("floor", (VisualPart(box_mesh((extent, extent, 0.001), (0.0, 0.0, -0.001)), VARIETY_FLOOR_COLOR, roughness=0.9),), ())
    _add_visual(scene, floor, np.eye(4), np.zeros(3))
    top = max(float(high[2]) for _, high in bounds)
    eye, target = _camera_seeing(np.array([-span[0] / 2, -span[1] / 2, 0.0]), np.array([span[0] / 2, span[1] / 2, top]))
    # SAPIEN's camera shader and picture format are process-wide, and an env made before may have left ManiSkill's
    # "minimal" pack (8-bit colour, no shadows) in place: ask for the default one, as ManiSkill does per camera
    sapien.render.set_camera_shader_dir("default")
    sapien.render.set_picture_format("Color", "r32g32b32a32sfloat")
    camera = scene.add_camera("variety", 2 * size, 2 * size, VARIETY_CAMERA_FOVY, 0.01, 10 * float(np.linalg.norm(eye - target)))
    camera.entity.set_pose(sapien.Pose(look_at(eye, target)))
    scene.update_render()
    camera.take_picture()
    rgb = (np.clip(camera.get_picture("Color")[..., :3], 0, 1) * 255).astype(np.uint8)
    return np.asarray(Image.fromarray(rgb).resize((size, size), Image.Resampling.LANCZOS))  # rendered at twice the size: smooth edges


def _camera_seeing(low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eye and target of the variety camera (looking along +x, ``VARIETY_CAMERA_ELEVATION`` down) that frames the box."""
    target = (low + high) / 2
    forward = np.array([np.cos(VARIETY_CAMERA_ELEVATION), 0.0, -np.sin(VARIETY_CAMERA_ELEVATION)])
    up = np.array([np.sin(VARIETY_CAMERA_ELEVATION), 0.0, np.cos(VARIETY_CAMERA_ELEVATION)])
    corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])]) - target
    tangent = np.tan(VARIETY_CAMERA_FOVY / 2) / 1.02  # a 2% margin
    depth = corners @ forward
    distance = max(np.max(np.abs(corners[:, 1]) / tangent - depth), np.max(np.abs(corners @ up) / tangent - depth))
    return target - distance * forward, target


def _kit_bounds(kit: list[Placed]) -> tuple[np.ndarray, np.ndarray]:
    corners = np.concatenate([asset.visual_mesh.bounds + pose[:3, 3] for asset, pose in kit])
    return corners.min(axis=0), corners.max(axis=0)


def _add_visual(scene: sapien.Scene, asset: Asset, pose: np.ndarray, offset: np.ndarray) -> None:
    body = sapien.render.RenderBodyComponent()
    for part in asset.visual_parts:
        body.attach(render_shape(part))
    entity = sapien.Entity()
    entity.add_component(body)
    placed = pose.copy()
    placed[:3, 3] += offset
    entity.set_pose(sapien.Pose(placed))
    scene.add_entity(entity)


def check_args(args: Args) -> None:
    """A ``ValueError`` naming the first bad input: an env id that is not ours, a size or rate below 1."""
    for env_id in args.env_ids:
        task_class(env_id)
    check_at_least("--steps", args.steps, 0)
    check_at_least("--image-size", args.image_size, 1)
    check_at_least("--fps", args.fps, 1)


def main(args: Args) -> None:
    with checking_inputs():
        check_args(args)
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


def cli(argv: Optional[Sequence[str]] = None) -> None:
    """``mani-skill-space showcase ARGS`` (and ``python -m mani_skill_space.showcase ARGS``)."""
    run_cli("showcase", tyro_parser(Args, "showcase", __doc__), main, argv)


if __name__ == "__main__":
    cli()
