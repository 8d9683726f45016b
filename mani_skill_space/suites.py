"""Benchmark suites: TOML files listing configurations (env id, kwargs, episodes, seed range).

    name = "smoke"
    episodes = 2          # defaults for every configuration
    seed_start = 1000

    [[configurations]]
    env_id = "SampleCollection-v1"
    kwargs = { domain = "mars", asset_source = "dataset" }
    episodes = 5          # optional: overrides the default
    seed_start = 0        # optional: seeds seed_start .. seed_start + episodes - 1

A configuration's env id must be one of ours. Every mistake is reported with the file and line.
"""

from __future__ import annotations

import inspect
import re
import tomllib
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path
from typing import Any, Callable, Optional

from mani_skill.envs.sapien_env import BaseEnv

from mani_skill_space.envs import TASKS
from mani_skill_space.envs.base import SpaceManipulationEnv
from mani_skill_space.kwarg_checks import KwargError

SUITE_KEYS = {"name", "description", "episodes", "seed_start", "configurations"}
CONFIGURATION_KEYS = {"name", "env_id", "kwargs", "episodes", "seed_start"}


class SuiteError(ValueError):
    pass


@dataclass(frozen=True)
class Configuration:
    name: str
    env_id: str
    kwargs: dict[str, Any]
    episodes: int
    seed_start: int
    line: int
    """Line of the configuration's ``[[configurations]]`` header in the suite file."""

    @property
    def seeds(self) -> list[int]:
        return list(range(self.seed_start, self.seed_start + self.episodes))


@dataclass(frozen=True)
class Suite:
    name: str
    path: Path
    description: str = ""
    configurations: tuple[Configuration, ...] = field(default_factory=tuple)


SHIPPED_SUITES_PACKAGE = "mani_skill_space.tasks"
"""The package holding the suites that ship with mani-skill-space (the repository's ``tasks/`` folder)."""


def shipped_suites() -> list[str]:
    """Names of the suites that ship inside the package (``smoke``, ...), sorted."""
    return sorted(entry.name.removesuffix(".toml") for entry in files(SHIPPED_SUITES_PACKAGE).iterdir() if entry.name.endswith(".toml"))


def suite_path(path_or_name: str | Path) -> Path:
    """The file of a suite given by path or by the name of a shipped suite.

    A name (no ``/``, no ``.toml`` suffix, not an existing file) such as ``smoke`` is the shipped
    ``smoke.toml``; anything else is a path.
    """
    text = str(path_or_name)
    if "/" in text or text.endswith(".toml") or Path(text).is_file():
        path = Path(path_or_name)
        if not path.is_file():
            raise SuiteError(f"{path}: no such suite file; shipped suites: {', '.join(shipped_suites())}")
        return path
    shipped = files(SHIPPED_SUITES_PACKAGE).joinpath(f"{text}.toml")
    if not shipped.is_file():
        raise SuiteError(f"unknown suite {text!r}; shipped suites: {', '.join(shipped_suites())} (or give the path of a .toml file)")
    return Path(str(shipped))


def load_suite(path_or_name: str | Path) -> Suite:
    """Load a suite from a file, or a shipped suite by name (``load_suite("smoke")``)."""
    path = suite_path(path_or_name)
    text = path.read_text()
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise SuiteError(f"{path}: {error}") from None
    locate = _Locator(path, text)
    reject_unknown_keys(data, SUITE_KEYS, "suite key", lambda key: locate.where(None, key))
    default_episodes = _positive_int(data.get("episodes", 10), locate, None, "episodes")
    default_seed_start = _natural_int(data.get("seed_start", 0), locate, None, "seed_start")
    entries = data.get("configurations", [])
    if not isinstance(entries, list) or not entries:
        raise SuiteError(f"{path}: a suite needs at least one [[configurations]] table")
    configurations = [_configuration(entry, i, locate, default_episodes, default_seed_start) for i, entry in enumerate(entries)]
    names = [c.name for c in configurations]
    for c in configurations:
        if names.count(c.name) > 1:
            raise SuiteError(f"{locate.where(names.index(c.name), None)}: duplicate configuration name {c.name!r}")
    return Suite(data.get("name", path.stem), path, data.get("description", ""), tuple(configurations))


def _configuration(entry: dict, index: int, locate: "_Locator", episodes: int, seed_start: int) -> Configuration:
    reject_unknown_keys(entry, CONFIGURATION_KEYS, "configuration key", lambda key: locate.where(index, key))
    env_id = entry.get("env_id")
    if env_id is None:
        raise SuiteError(f"{locate.where(index, None)}: configuration without env_id")
    if env_id not in TASKS:
        valid = ", ".join(TASKS)
        raise SuiteError(f"{locate.where(index, 'env_id')}: unknown env id {env_id!r}; valid choices: {valid}")
    kwargs = entry.get("kwargs", {})
    if not isinstance(kwargs, dict):
        raise SuiteError(f"{locate.where(index, 'kwargs')}: kwargs must be a table")
    _check_kwargs(TASKS[env_id], kwargs, locate, index)
    return Configuration(
        name=entry.get("name") or _default_name(env_id, kwargs),
        env_id=env_id,
        kwargs=kwargs,
        episodes=_positive_int(entry.get("episodes", episodes), locate, index, "episodes"),
        seed_start=_natural_int(entry.get("seed_start", seed_start), locate, index, "seed_start"),
        line=locate.header_line(index),
    )


def _check_kwargs(env_class: type[SpaceManipulationEnv], kwargs: dict, locate: "_Locator", index: int) -> None:
    """The configuration's kwargs checked as the env will check them, reported at the line of the offending key."""
    try:
        check_env_kwargs(env_class, kwargs)
    except KwargError as error:
        raise SuiteError(f"{locate.where(index, error.kwarg)}: {error}") from None


def check_env_kwargs(env_class: type[SpaceManipulationEnv], kwargs: dict) -> dict:
    """``kwargs`` checked for ``env_class`` without building a scene: every name one that its constructors take,
    every value of ours (and ManiSkill's control, observation and reward mode) one that the env accepts
    (``check_task_kwargs``, whose checked values are returned). A ``KwargError`` names the first bad kwarg."""
    accepted = accepted_kwargs(env_class)
    for key in kwargs:
        if key not in accepted:
            raise KwargError(key, f"{env_class.__name__} takes no kwarg {key!r}; valid choices: {', '.join(sorted(accepted))}")
    return env_class.check_task_kwargs(**kwargs)


def accepted_kwargs(env_class: type) -> set[str]:
    """Keyword arguments the env's constructor chain accepts (the task's, the base class's, ManiSkill's)."""
    names = set()
    for cls in env_class.__mro__:
        if cls is object or "__init__" not in vars(cls):
            continue
        for parameter in inspect.signature(cls.__init__).parameters.values():
            if parameter.kind in (parameter.POSITIONAL_OR_KEYWORD, parameter.KEYWORD_ONLY) and parameter.name != "self":
                names.add(parameter.name)
        if cls is BaseEnv:
            break
    return names


def _default_name(env_id: str, kwargs: dict) -> str:
    return env_id + "".join(f"/{value}" for value in kwargs.values())


def reject_unknown_keys(table: dict, allowed: set[str], what: str, where: Callable[[str], str]) -> None:
    """A ``SuiteError`` for the first key of ``table`` not in ``allowed``, located by ``where(key)``, naming the valid
    choices (suites and protocols)."""
    for key in table:
        if key not in allowed:
            raise SuiteError(f"{where(key)}: unknown {what} {key!r}; valid choices: {', '.join(sorted(allowed))}")


def _positive_int(value, locate: "_Locator", index: Optional[int], key: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 1:
        raise SuiteError(f"{locate.where(index, key)}: {key} must be a positive integer, got {value!r}")
    return value


def _natural_int(value, locate: "_Locator", index: Optional[int], key: str) -> int:
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise SuiteError(f"{locate.where(index, key)}: {key} must be a non-negative integer, got {value!r}")
    return value


class _Locator:
    """Finds the line of a key in the suite text (tomllib keeps no positions)."""

    HEADER = re.compile(r"^\s*\[\[\s*configurations\s*\]\]")

    def __init__(self, path: Path, text: str):
        self.path = path
        self.lines = text.splitlines()
        self.headers = [i for i, line in enumerate(self.lines) if self.HEADER.match(line)]

    def header_line(self, index: int) -> int:
        return self.headers[index] + 1 if index < len(self.headers) else 0

    def where(self, index: Optional[int], key: Optional[str]) -> str:
        if index is None:
            start, end = 0, self.headers[0] if self.headers else len(self.lines)
        else:
            start = self.headers[index] if index < len(self.headers) else 0
            end = self.headers[index + 1] if index + 1 < len(self.headers) else len(self.lines)
        line = start + 1
        if key is not None:
            pattern = re.compile(rf"(^|[\s{{,]){re.escape(key)}\s*=")
            for number in range(start, end):
                if pattern.search(self.lines[number].split("#")[0]):
                    line = number + 1
                    break
        return f"{self.path}:{line}"
