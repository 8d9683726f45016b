import textwrap
from pathlib import Path

import pytest

from mani_skill_space import suites
from mani_skill_space.envs import TASKS, task_class
from mani_skill_space.suites import SuiteError, accepted_kwargs, load_suite

GOOD = """
name = "tiny"
episodes = 3
seed_start = 7

[[configurations]]
env_id = "SampleCollection-v1"
kwargs = { domain = "moon", asset_source = "dataset" }

[[configurations]]
name = "later"
env_id = "PegInHoleAssembly-v1"
episodes = 1
"""


def _write(tmp_path, text):
    path = tmp_path / "suite.toml"
    path.write_text(textwrap.dedent(text))
    return path


def test_a_suite_lists_its_configurations_with_seed_ranges(tmp_path):
    suite = load_suite(_write(tmp_path, GOOD))
    first, later = suite.configurations
    assert suite.name == "tiny"
    assert first.name == "SampleCollection-v1/moon/dataset" and first.seeds == [7, 8, 9]
    assert later.name == "later" and later.env_id == "PegInHoleAssembly-v1" and later.seeds == [7]
    assert first.line == 6


@pytest.mark.parametrize(
    "old, new, expected, line",
    [
        ('"SampleCollection-v1"', '"Samplecollection-v1"', "unknown env id 'Samplecollection-v1'", 7),
        ('domain = "moon"', 'domain = "venus"', "unknown domain 'venus'; valid choices: moon, mars, earth, asteroid", 8),
        ('domain = "moon"', 'domian = "moon"', "takes no kwarg 'domian'", 8),
        ('asset_source = "dataset"', 'asset_source = "cad"', "unknown asset_source 'cad'; valid choices: procedural, dataset", 8),
        ("episodes = 1", "episodes = 0", "episodes must be a positive integer", 13),
        ("episodes = 1", "episode = 1", "unknown configuration key 'episode'", 13),
    ],
)
def test_bad_suites_name_the_offending_line(tmp_path, old, new, expected, line):
    path = _write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(SuiteError) as error:
        load_suite(path)
    assert expected in str(error.value)
    assert str(error.value).startswith(f"{path}:{line}:"), str(error.value)


def test_malformed_toml_is_reported_with_the_file(tmp_path):
    path = _write(tmp_path, "name = [unclosed\n")
    with pytest.raises(SuiteError, match="suite.toml"):
        load_suite(path)


def test_shipped_smoke_suite_covers_every_task_domain_and_asset_source():
    suite = load_suite("tasks/smoke.toml")
    covered = {(c.env_id, c.kwargs["domain"], c.kwargs["asset_source"]) for c in suite.configurations}
    expected = {(env_id, d, s) for env_id, cls in TASKS.items() for d in cls.SUPPORTED_DOMAINS for s in cls.SUPPORTED_ASSET_SOURCES}
    assert covered == expected


def test_shipped_corl2024_suite_has_the_papers_six_configurations_of_200_episodes():
    suite = load_suite("tasks/corl2024.toml")
    assert len(suite.configurations) == 6
    assert all(c.episodes == 200 for c in suite.configurations)
    tubes = next(c for c in suite.configurations if c.name == "sample-collection/sample-tubes")
    assert tubes.kwargs == {"domain": "mars", "asset_source": "dataset"}


def test_accepted_kwargs_cover_the_task_the_base_class_and_maniskill():
    accepted = accepted_kwargs(task_class("SampleCollection-v1"))
    assert {"domain", "asset_source", "robot_init_qpos_noise", "obs_mode", "control_mode", "sim_config", "num_envs"} <= accepted


@pytest.mark.parametrize("path", sorted(Path("tasks").glob("*.toml")), ids=lambda p: p.name)
def test_every_shipped_suite_loads(path):
    suite = load_suite(path)
    assert suite.configurations and all(c.env_id in TASKS for c in suite.configurations)


def test_shipped_suites_are_the_repositorys_tasks_folder():
    assert suites.shipped_suites() == sorted(path.stem for path in Path("tasks").glob("*.toml"))
    assert "smoke" in suites.shipped_suites()


def test_a_suite_name_loads_the_shipped_suite(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    suite = load_suite("smoke")
    assert suite.name == "smoke"
    assert suite.path.parent.name == "tasks" and suite.path.is_file()
    assert suite == load_suite(suite.path)


def test_a_path_wins_over_a_shipped_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _write(tmp_path, GOOD).rename(tmp_path / "smoke")
    assert load_suite("smoke").name == "tiny"
    assert load_suite(Path("smoke")).name == "tiny"


def test_an_unknown_suite_name_lists_the_shipped_suites(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SuiteError) as error:
        load_suite("smok")
    message = str(error.value)
    assert "unknown suite 'smok'" in message
    assert all(name in message for name in suites.shipped_suites())


@pytest.mark.parametrize("missing", ["missing.toml", "nowhere/suite.toml"])
def test_a_missing_suite_file_is_a_suite_error_naming_the_file(tmp_path, monkeypatch, missing):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SuiteError, match=f"^{missing}: no such suite file; shipped suites: .*smoke"):
        load_suite(missing)
