"""Score every checkpoint of the manifest with the evaluation CLI, on the seeds the manifest lists.

    python baselines/score_checkpoints.py                      # baselines/checkpoints/manifest.toml, every seed
    python baselines/score_checkpoints.py --episodes 2         # a quick check that each loads and runs
    python baselines/score_checkpoints.py --only bc_solar_ee   # score one entry again, keep the others' rows

Writes ``<output>.json`` and ``<output>.md`` (the README's baseline table: every checkpoint's success with 95% Wilson
intervals next to the success its manifest entry records).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import tyro

from mani_skill_space import eval as evaluation
from mani_skill_space.learning.manifest import load_manifest
from mani_skill_space.metrics import any_staged, format_rate, stage_cell
from mani_skill_space.protocol import condition_label
from mani_skill_space.suites import Configuration, Suite

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Args:
    manifest: Path = ROOT / "baselines" / "checkpoints" / "manifest.toml"
    output: Path = ROOT / "baselines" / "results" / "checkpoints"
    episodes: Optional[int] = None
    """Score only the first N of each entry's seeds."""
    num_workers: int = os.cpu_count() or 1
    only: tuple[str, ...] = ()
    """Score only these entries; every other entry keeps its row from the earlier ``<output>.json``."""


def main(args: Args) -> list[dict]:
    entries = load_manifest(args.manifest)
    kept = earlier_rows(args, [entry.name for entry in entries])
    rows = []
    for entry in entries:
        if entry.name in kept:
            rows.append(kept[entry.name])
            continue
        suite = Suite(entry.name, args.manifest, configurations=(Configuration(entry.name, entry.env_id, entry.kwargs, entry.episodes, entry.seed_start, line=0),))
        run_args = evaluation.Args(suite=args.manifest, policy=(entry.policy,), episodes=args.episodes, num_workers=args.num_workers)
        (row,) = evaluation.evaluate(suite, run_args)["rows"]
        rows.append(dict(name=entry.name, env_id=entry.env_id, kwargs=entry.kwargs, command=entry.command, manifest_success_at_end=entry.success_at_end, summary=row["summary"], seeds=[e["seed"] for e in row["episodes"]]))
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.with_suffix(".json").write_text(json.dumps(rows, indent=1) + "\n")
    table = markdown_table(rows)
    args.output.with_suffix(".md").write_text(table + "\n")
    print(table)
    return rows


def earlier_rows(args: Args, names: list[str]) -> dict[str, dict]:
    """The rows of the entries ``--only`` leaves out, from the earlier output (none without ``--only``)."""
    if not args.only:
        return {}
    unknown = sorted(set(args.only) - set(names))
    if unknown:
        raise ValueError(f"--only names {unknown}, which {args.manifest} does not list; valid choices: {', '.join(names)}")
    earlier_path = args.output.with_suffix(".json")
    earlier = {row["name"]: row for row in json.loads(earlier_path.read_text())} if earlier_path.exists() else {}
    missing = [name for name in names if name not in args.only and name not in earlier]
    if missing:
        raise ValueError(f"{earlier_path} has no rows for {missing}, which --only leaves out: score them too")
    return {name: earlier[name] for name in names if name not in args.only}


def markdown_table(rows: list[dict]) -> str:
    """One line per checkpoint; where any scored env is staged (Solar Panel Assembly: sockets filled), a column with
    the mean highest stage, as the evaluation CLI's table has."""
    staged = any_staged(row["summary"] for row in rows)
    lines = [
        "| checkpoint | env | kwargs | episodes (seeds) | success_once | success_at_end | return |" + (" stage |" if staged else "") + " manifest |",
        "|---|---|---|---|---|---|---|" + ("---|" if staged else "") + "---|",
    ]
    for row in rows:
        s = row["summary"]
        kwargs = condition_label(row["kwargs"])
        seeds = f"{s['episodes']} ({row['seeds'][0]}-{row['seeds'][-1]})"
        stage = f" {stage_cell(s)} |" if staged else ""
        lines.append(
            f"| {row['name']} | {row['env_id']} | {kwargs} | {seeds} | {format_rate(s['success_once'], s['success_once_ci95'], decimals=0)} "
            f"| {format_rate(s['success_at_end'], s['success_at_end_ci95'], decimals=0)} | {s['return_mean']:.2f} |{stage} {100 * row['manifest_success_at_end']:.0f}% |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    main(tyro.cli(Args))
