"""The GPU suite: the batched path (``num_envs > 1``, ``sim_backend="physx_cuda"``) of every task.

Every test under ``tests/gpu`` gets the ``gpu`` marker and is skipped where CUDA is not available
(``torch.cuda.is_available()`` is False), so the suite is collected, and checked to skip cleanly, on CPU machines.
On a machine with a GPU, one command runs it::

    pytest -m gpu tests/gpu

SAPIEN's GPU PhysX can only be enabled in a process before any other PhysX code ran (a CPU env included). When GPU
tests are selected and CUDA is available, it is enabled right after collection, before any test runs, so that a run
that also selects CPU tests still works; a failure to enable it (e.g. the PhysX GPU library, which SAPIEN downloads
to ``~/.sapien/physx/<version>/`` on first use, is missing on an offline machine) fails every GPU test with the reason.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import pytest
import torch

HERE = Path(__file__).parent.resolve()
CUDA_AVAILABLE = torch.cuda.is_available()
SKIP_REASON = "needs CUDA for ManiSkill's GPU simulation (physx_cuda): torch.cuda.is_available() is False; run with a GPU: pytest -m gpu tests/gpu"

_gpu_physx_error: Optional[str] = None


def _under_this_folder(item: pytest.Item) -> bool:
    return HERE in Path(str(item.path)).resolve().parents


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test of this folder ``gpu`` (before ``-m`` selects by marker) and skip it without CUDA. The hook
    sees the whole session's items: those of other folders are left as they are."""
    for item in items:
        if _under_this_folder(item):
            item.add_marker(pytest.mark.gpu)
            if not CUDA_AVAILABLE:
                item.add_marker(pytest.mark.skip(reason=SKIP_REASON))


@pytest.hookimpl(trylast=True)
def pytest_collection_finish(session: pytest.Session) -> None:
    """With CUDA and GPU tests selected, enable SAPIEN's GPU PhysX before any test (CPU ones included) uses PhysX."""
    global _gpu_physx_error
    if not CUDA_AVAILABLE or session.config.option.collectonly or not any(_under_this_folder(item) for item in session.items):
        return
    import sapien.physx as physx

    try:
        physx.enable_gpu()
    except Exception as error:  # noqa: BLE001 - reported by every GPU test below
        _gpu_physx_error = f"{type(error).__name__}: {error}"


@pytest.fixture(autouse=True, scope="session")
def _gpu_physx_enabled():
    if _gpu_physx_error is not None:
        pytest.fail(
            f"could not enable SAPIEN's GPU PhysX ({_gpu_physx_error}); it needs the PhysX GPU library in "
            "~/.sapien/physx/<version>/ (SAPIEN downloads it on first use) and no PhysX code run before in the process",
            pytrace=False,
        )
    yield
