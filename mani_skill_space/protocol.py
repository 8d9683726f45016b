"""Generalisation protocols: a training condition, held-out test conditions, and the gap between them.

A protocol (``tasks/generalisation/*.toml``) names the condition a policy was trained in and the conditions it
is tested in, each given as env kwargs that replace the training condition's (everything else held):

    name = "levels"
    episodes = 100        # per cell (a test may override it)
    seed_start = 20000    # episode seeds of every cell

    [train]               # the training condition of policies that record none (a checkpoint records its own)
    env_id = "SampleCollection-v1"
    kwargs = { domain = "mars", asset_source = "procedural", num_levels = 100 }

    [[tests]]
    name = "held-out levels"
    kwargs = { num_levels = 0, start_level = 1000000 }

Scoring a policy gives one row of the matrix: its training condition (a checkpoint's env kwargs, or ``[train]``)
evaluated on fresh episode seeds (the in-distribution cell, column ``train``), then every test, each cell with
its 95% Wilson interval, and the generalisation gap of every test: in-distribution minus held-out success, with
Newcombe's hybrid score interval for a difference of independent proportions.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Any, Optional

from mani_skill_space.envs import TASKS
from mani_skill_space.kwarg_checks import RUN_KWARGS, KwargError
from mani_skill_space.metrics import format_rate, wilson_interval
from mani_skill_space.suites import SHIPPED_SUITES_PACKAGE, Configuration, Suite, SuiteError, check_env_kwargs, reject_unknown_keys

PROTOCOL_KEYS = {"name", "description", "episodes", "seed_start", "train", "tests"}
TRAIN_KEYS = {"env_id", "kwargs"}
TEST_KEYS = {"name", "kwargs", "episodes"}
IN_DISTRIBUTION = "train"
"""Name of the in-distribution column (the training condition on fresh episode seeds)."""
PROTOCOLS_FOLDER = "generalisation"
MANISKILL_CONFIG_KWARGS = RUN_KWARGS + ("obs_mode", "control_mode")
"""Env kwargs a recorded training condition may carry that say how the env was run, not which task it was."""


@dataclass(frozen=True)
class Test:
    name: str
    kwargs: dict[str, Any]
    episodes: int


@dataclass(frozen=True)
class Protocol:
    name: str
    path: Path
    env_id: str
    train_kwargs: dict[str, Any]
    tests: tuple[Test, ...]
    episodes: int
    seed_start: int
    description: str = ""


def shipped_protocols() -> list[str]:
    folder = files(SHIPPED_SUITES_PACKAGE).joinpath(PROTOCOLS_FOLDER)
    return sorted(entry.name.removesuffix(".toml") for entry in folder.iterdir() if entry.name.endswith(".toml"))


def protocol_path(path_or_name: str | Path) -> Path:
    """The file of a protocol given by path, or by the name of a shipped one (``levels``)."""
    text = str(path_or_name)
    if "/" in text or text.endswith(".toml") or Path(text).is_file():
        if not Path(text).is_file():
            raise SuiteError(f"{text}: no such protocol file; shipped protocols: {', '.join(shipped_protocols())}")
        return Path(text)
    shipped = files(SHIPPED_SUITES_PACKAGE).joinpath(PROTOCOLS_FOLDER, f"{text}.toml")
    if not shipped.is_file():
        raise SuiteError(f"unknown protocol {text!r}; shipped protocols: {', '.join(shipped_protocols())} (or give the path of a .toml file)")
    return Path(str(shipped))


def load_protocol(path_or_name: str | Path) -> Protocol:
    """Load and check a protocol: every test's kwargs, merged onto ``[train]``, are ones the env accepts."""
    path = protocol_path(path_or_name)
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as error:
        raise SuiteError(f"{path}: {error}") from None
    _reject_unknown(data, PROTOCOL_KEYS, f"{path}", "protocol key")
    train = data.get("train")
    if not isinstance(train, dict) or "env_id" not in train:
        raise SuiteError(f"{path}: a protocol needs a [train] table with env_id (and kwargs)")
    _reject_unknown(train, TRAIN_KEYS, f"{path}: [train]", "key")
    if train["env_id"] not in TASKS:
        raise SuiteError(f"{path}: [train]: unknown env id {train['env_id']!r}; valid choices: {', '.join(TASKS)}")
    episodes = _positive(data.get("episodes", 50), f"{path}: episodes")
    seed_start = data.get("seed_start", 0)
    if not isinstance(seed_start, int) or isinstance(seed_start, bool) or seed_start < 0:
        raise SuiteError(f"{path}: seed_start must be a non-negative integer, got {seed_start!r}")
    entries = data.get("tests", [])
    if not isinstance(entries, list) or not entries:
        raise SuiteError(f"{path}: a protocol needs at least one [[tests]] table")
    tests = []
    for index, entry in enumerate(entries):
        where = f"{path}: [[tests]] {index + 1}"
        _reject_unknown(entry, TEST_KEYS, where, "key")
        name = entry.get("name")
        if not isinstance(name, str) or not name or name == IN_DISTRIBUTION or name in [t.name for t in tests]:
            raise SuiteError(f"{where}: every test needs a unique name other than {IN_DISTRIBUTION!r}, got {name!r}")
        tests.append(Test(name, dict(entry.get("kwargs", {})), _positive(entry.get("episodes", episodes), f"{where}: episodes")))
    protocol = Protocol(data.get("name", path.stem), path, train["env_id"], dict(train.get("kwargs", {})), tuple(tests), episodes, seed_start, data.get("description", ""))
    protocol_suite(protocol, protocol.env_id, protocol.train_kwargs)  # checks every cell's kwargs
    return protocol


def task_kwargs(kwargs: dict[str, Any]) -> dict[str, Any]:
    """A recorded condition without the kwargs that only say how the env was run (cameras' shaders, modes)."""
    return {key: value for key, value in kwargs.items() if key not in MANISKILL_CONFIG_KWARGS}


def protocol_suite(protocol: Protocol, env_id: str, train_kwargs: dict[str, Any]) -> Suite:
    """The cells of one row as a suite: the training condition (``train``), then every test's kwargs merged onto
    it. Raises a ``SuiteError`` naming the cell whose kwargs the env would refuse."""
    if env_id != protocol.env_id:
        raise SuiteError(f"{protocol.path}: the protocol tests {protocol.env_id}; a policy trained on {env_id} cannot be scored on it")
    cells = [(IN_DISTRIBUTION, dict(train_kwargs), protocol.episodes)] + [(t.name, {**train_kwargs, **t.kwargs}, t.episodes) for t in protocol.tests]
    configurations = []
    for name, kwargs, episodes in cells:
        try:
            check_env_kwargs(TASKS[env_id], kwargs)
        except KwargError as error:
            raise SuiteError(f"{protocol.path}: cell {name!r}: {error}") from None
        configurations.append(Configuration(name=name, env_id=env_id, kwargs=kwargs, episodes=episodes, seed_start=protocol.seed_start, line=0))
    return Suite(protocol.name, protocol.path, protocol.description, tuple(configurations))


def condition_label(kwargs: dict[str, Any]) -> str:
    return ", ".join(f"{key}={value}" for key, value in task_kwargs(kwargs).items()) or "defaults"


def newcombe_interval(successes_a: int, trials_a: int, successes_b: int, trials_b: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """95% interval for the difference of two independent proportions a - b (Newcombe 1998, method 10: the
    hybrid of the two Wilson score intervals)."""
    p_a, p_b = successes_a / trials_a, successes_b / trials_b
    low_a, high_a = wilson_interval(successes_a, trials_a, z)
    low_b, high_b = wilson_interval(successes_b, trials_b, z)
    difference = p_a - p_b
    return (
        difference - math.sqrt((p_a - low_a) ** 2 + (high_b - p_b) ** 2),
        difference + math.sqrt((high_a - p_a) ** 2 + (p_b - low_b) ** 2),
    )


def matrix_row(policy: str, training_kwargs: dict[str, Any], report_rows: list[dict], metric: str = "success_at_end") -> dict:
    """One row of the matrix from the evaluation's rows (one per cell): every cell's summary and the gap of each
    test (``train`` minus the test, on ``metric``) with Newcombe's interval."""
    cells = {row["configuration"]: row["summary"] for row in report_rows}
    successes = {row["configuration"]: sum(bool(e[metric]) for e in row["episodes"]) for row in report_rows}
    trained = cells[IN_DISTRIBUTION]
    gaps = {}
    for name, summary in cells.items():
        if name == IN_DISTRIBUTION:
            continue
        gaps[name] = dict(
            gap=trained[metric] - summary[metric],
            ci95=newcombe_interval(successes[IN_DISTRIBUTION], trained["episodes"], successes[name], summary["episodes"]),
        )
    return dict(policy=policy, training_condition=task_kwargs(training_kwargs), label=condition_label(training_kwargs), cells=cells, gaps=gaps)


def markdown_matrix(matrix: dict) -> str:
    metric = matrix["metric"]
    columns = matrix["columns"]
    lines = [
        f"Protocol `{matrix['protocol']}`: {metric} with 95% Wilson intervals; gap = `{IN_DISTRIBUTION}` minus the test, with Newcombe's 95% interval.",
        "",
        "| policy | training condition | " + " | ".join(columns) + " |",
        "|---|---|" + "---|" * len(columns),
    ]
    for row in matrix["rows"]:
        cells = [format_rate(row["cells"][c][metric], row["cells"][c][f"{metric}_ci95"], decimals=0) for c in columns]
        lines.append(f"| {row['policy']} | {row['label']} | " + " | ".join(cells) + " |")
    lines += ["", "| policy | " + " | ".join(f"gap: {c}" for c in columns[1:]) + " |", "|---|" + "---|" * (len(columns) - 1)]
    for row in matrix["rows"]:
        lines.append(f"| {row['policy']} | " + " | ".join(_points(row["gaps"][c]["gap"], row["gaps"][c]["ci95"]) for c in columns[1:]) + " |")
    return "\n".join(lines)


def _points(gap: float, interval) -> str:
    return f"{100 * gap:+.0f} [{100 * interval[0]:+.0f}, {100 * interval[1]:+.0f}]"


def heat_map(matrix: dict, path: Path) -> Optional[Path]:
    """The matrix as a heat-map PNG (success of every cell, annotated with its interval); None without
    matplotlib (``pip install "mani-skill-space[baselines]"``)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    metric, columns, rows = matrix["metric"], matrix["columns"], matrix["rows"]
    values = [[row["cells"][c][metric] for c in columns] for row in rows]
    figure, axes = plt.subplots(figsize=(1.6 + 1.5 * len(columns), 1.2 + 0.6 * len(rows)))
    image = axes.imshow(values, vmin=0.0, vmax=1.0, cmap="viridis", aspect="auto")
    for i, row in enumerate(rows):
        for j, column in enumerate(columns):
            low, high = row["cells"][column][f"{metric}_ci95"]
            colour = "white" if values[i][j] < 0.6 else "black"
            axes.text(j, i, f"{100 * values[i][j]:.0f}%\n[{100 * low:.0f}, {100 * high:.0f}]", ha="center", va="center", fontsize=8, color=colour)
    axes.set_xticks(range(len(columns)), columns, rotation=30, ha="right")
    axes.set_yticks(range(len(rows)), [f"{row['policy']}\n({row['label']})" for row in rows], fontsize=7)
    axes.set_title(f"{matrix['protocol']}: {metric}")
    figure.colorbar(image, ax=axes, fraction=0.04)
    figure.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(figure)
    return path


def _positive(value: Any, where: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise SuiteError(f"{where} must be a positive integer, got {value!r}")
    return value


def _reject_unknown(table: Any, allowed: set[str], where: str, what: str) -> None:
    if not isinstance(table, dict):
        raise SuiteError(f"{where}: expected a table")
    reject_unknown_keys(table, allowed, what, lambda key: where)
