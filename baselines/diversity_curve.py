"""The diversity curve: held-out success of policies trained on demonstrations from 1, 10, 100, ... levels.

Each checkpoint is scored on a generalisation protocol (``tasks/generalisation/levels.toml`` by default: its own
training levels on fresh seeds, 100 held-out levels from 1,000,000 on, and the dataset's tubes); its demonstration
file says how many distinct levels it learned from. Writes ``<output>.csv`` (one row per checkpoint: training
levels, levels in its demonstrations, every cell's success_at_end with its 95% Wilson interval, and the gap to each
test with Newcombe's interval), ``<output>.png`` (success against the number of training levels, log x) and the
protocol's matrix (``<output>_matrix.{json,md,png}``).

    python baselines/diversity_curve.py --checkpoints runs/bc_levels{1,10,100,1000}/best.pt \\
        --demos demos/SampleCollection-v1/motionplanning/levels{1,10,100,1000}.h5 --output baselines/results/diversity_sample_collection
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass
from pathlib import Path

import tyro

from mani_skill_space import eval as evaluation
from mani_skill_space.learning import load_checkpoint
from mani_skill_space.levels import LevelRange
from mani_skill_space.protocol import heat_map, load_protocol, markdown_matrix


@dataclass
class Args:
    checkpoints: tuple[Path, ...]
    demos: tuple[Path, ...]
    """The demonstration file each checkpoint learned from, in the same order."""
    protocol: str = "levels"
    output: Path = Path("baselines/results/diversity_sample_collection")
    num_workers: int = os.cpu_count() or 1


def levels_in_demonstrations(demos: Path, level_range: LevelRange) -> tuple[int, int]:
    """(successful demonstrations, distinct levels among them) of a trajectory file recorded with one env."""
    episodes = [e for e in json.loads(Path(demos).with_suffix(".json").read_text())["episodes"] if e.get("success")]
    return len(episodes), len({level_range.level_of(e["episode_seed"]) for e in episodes})


def main(args: Args) -> list[dict]:
    if len(args.checkpoints) != len(args.demos):
        raise SystemExit("diversity_curve: give one --demos file per --checkpoints file")
    protocol = load_protocol(args.protocol)
    matrix = evaluation.evaluate_protocol(protocol, evaluation.Args(protocol=Path(args.protocol), policy=tuple(f"checkpoint:{c}" for c in args.checkpoints), num_workers=args.num_workers))
    rows = []
    for checkpoint, demos, row in zip(args.checkpoints, args.demos, matrix["rows"]):
        kwargs = load_checkpoint(checkpoint)["env_kwargs"]
        level_range = LevelRange(kwargs.get("num_levels", 0), kwargs.get("start_level", 0))
        count, distinct = levels_in_demonstrations(demos, level_range)
        entry = dict(num_levels=level_range.num_levels, levels_in_demos=distinct, demonstrations=count, checkpoint=str(checkpoint))
        for column in matrix["columns"]:
            cell = row["cells"][column]
            entry[f"{column}: success"] = cell["success_at_end"]
            entry[f"{column}: ci_low"], entry[f"{column}: ci_high"] = cell["success_at_end_ci95"]
        for column, gap in row["gaps"].items():
            entry[f"gap {column}"] = gap["gap"]
            entry[f"gap {column}: ci_low"], entry[f"gap {column}: ci_high"] = gap["ci95"]
        rows.append(entry)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    with args.output.with_suffix(".csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    matrix_stem = args.output.parent / f"{args.output.name}_matrix"
    matrix_stem.with_suffix(".json").write_text(json.dumps(matrix, indent=1) + "\n")
    matrix_stem.with_suffix(".md").write_text(markdown_matrix(matrix) + "\n")
    heat_map(matrix, matrix_stem.with_suffix(".png"))
    plot(rows, matrix["columns"], args.output.with_suffix(".png"), protocol.env_id)
    print(markdown_matrix(matrix))
    return rows


def plot(rows: list[dict], columns: list[str], path: Path, env_id: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(6, 4))
    levels = [row["num_levels"] for row in rows]
    for column in columns:
        success = [row[f"{column}: success"] for row in rows]
        errors = [[s - row[f"{column}: ci_low"] for s, row in zip(success, rows)], [row[f"{column}: ci_high"] - s for s, row in zip(success, rows)]]
        axes.errorbar(levels, success, yerr=errors, marker="o", capsize=3, label=column)
    axes.set_xscale("log")
    axes.set_ylim(-0.02, 1.02)
    axes.set_xlabel("training levels (num_levels)")
    axes.set_ylabel("success_at_end (95% CI)")
    axes.set_title(f"{env_id}: BC, same number of demonstrations per run")
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


if __name__ == "__main__":
    main(tyro.cli(Args))
