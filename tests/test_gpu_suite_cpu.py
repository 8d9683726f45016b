"""The GPU suite (``tests/gpu``) as seen from a machine without CUDA: it is collected, every test of it carries the
``gpu`` marker and skips with its reason, its configurations cover every task, domain and asset source, and its
benchmark refuses to run in one line. (Checked here, outside ``tests/gpu``, where everything needs CUDA.)"""

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import mani_skill_space
from mani_skill_space.envs import task_class

ROOT = Path(__file__).resolve().parents[1]
GPU_DIR = ROOT / "tests" / "gpu"

needs_no_cuda = pytest.mark.skipif(torch.cuda.is_available(), reason="checks the behaviour without CUDA; this machine has CUDA")


def _run(*command: str, timeout: int = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *command], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def _pytest(*arguments: str) -> subprocess.CompletedProcess:
    return _run("-m", "pytest", "tests/gpu", "-p", "no:cacheprovider", *arguments)


def _gpu_test_module():
    """``tests/gpu/test_gpu_envs.py`` loaded on its own (its dataclasses need it in ``sys.modules``)."""
    name = "gpu_suite_under_test"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, GPU_DIR / "test_gpu_envs.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


def _count(outcome: str, summary: str) -> int:
    found = re.search(rf"(\d+) {outcome}", summary)
    return int(found.group(1)) if found else 0


@needs_no_cuda
def test_the_gpu_bench_without_cuda_is_one_line_on_stderr_and_exit_status_2():
    result = _run(str(GPU_DIR / "bench_gpu.py"))
    assert result.returncode == 2, result.stderr[-2000:]
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("mani-skill-space bench-gpu: error: ") and "CUDA" in lines[0]


@needs_no_cuda
def test_every_gpu_test_is_gpu_marked_and_skipped_without_cuda():
    module = _gpu_test_module()
    per_configuration = [name for name in vars(module.TestBatchedEnv) if name.startswith("test_")]
    expected = len(module.CONFIGURATIONS) * len(per_configuration)

    run = _pytest("-q", "-rs")
    output = run.stdout + run.stderr
    assert run.returncode == 0, output[-3000:]
    summary = output.strip().splitlines()[-1]
    assert "skipped" in summary and "failed" not in summary and "error" not in summary and "passed" not in summary, summary
    assert _count("skipped", summary) == expected, summary
    assert "SKIPPED" in output and "needs CUDA" in output and "torch.cuda.is_available() is False" in output

    # every collected test carries the marker: `-m "not gpu"` leaves none, `-m gpu` keeps them all
    not_gpu = _pytest("--collect-only", "-q", "-m", "not gpu")
    assert not_gpu.returncode == 5, not_gpu.stdout[-2000:]  # 5: no tests collected
    assert f"{expected} deselected" in not_gpu.stdout, not_gpu.stdout[-2000:]
    gpu = _pytest("--collect-only", "-q", "-m", "gpu")
    assert gpu.returncode == 0, gpu.stdout[-2000:]
    assert f"{expected} tests collected" in gpu.stdout, gpu.stdout[-2000:]


def test_the_gpu_configurations_cover_every_task_domain_and_asset_source():
    expected = {
        (env_id, domain, source)
        for env_id in mani_skill_space.ENV_IDS
        for domain in task_class(env_id).SUPPORTED_DOMAINS
        for source in task_class(env_id).SUPPORTED_ASSET_SOURCES
    }
    module = _gpu_test_module()
    assert len(module.CONFIGURATIONS) == len(set(module.CONFIGURATIONS)) == len(expected)
    assert set(module.CONFIGURATIONS) == expected
    assert set(module.SINGLE_MODEL_DATASET) <= set(mani_skill_space.ENV_IDS)
    assert "orbit" in {domain for _, domain, _ in module.CONFIGURATIONS}
