"""The offline GPU bundle (``tools/gpu_bundle.sh``) and its wheel trimmer (``tools/trim_wheel.py``).

The slow test builds the bundle for this machine's Python (``--python-version host``; the GPU machine's is 3.12),
checks the parts' sizes (at most two, each at most 64 MiB: what the device tool carries a call) and the trimmed
mani-skill wheel, then runs ``check-install``: the bundle installed offline into a fresh venv that sees nothing but the
bundle and the packages the target is declared to have (torch, numpy, ...), where ``import mani_skill_space`` and
``gym.make("SampleCollection-v1", obs_mode="state")`` + reset + step (and the bench peers) work. It downloads the
wheels from PyPI (pip's cache makes later runs quick).
"""

from __future__ import annotations

import base64
import csv
import hashlib
import io
import os
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
TOOLS = REPO / "tools"
PART_LIMIT = 64 * 2**20
BUNDLE = "mani_skill_space_gpu_bundle"


def _hash(data: bytes) -> str:
    return "sha256=" + base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()


def _tiny_wheel(folder: Path) -> Path:
    """A valid pure-python wheel ``tinypkg-1.0`` with a data folder to trim."""
    files = {
        "tinypkg/__init__.py": b"from pathlib import Path\nHERE = Path(__file__).parent\n",
        "tinypkg/data/keep.txt": b"needed\n",
        "tinypkg/data/big.bin": os.urandom(4096),
        "tinypkg/data/sub/other.bin": os.urandom(1024),
        "tinypkg/extra.txt": b"kept: no rule matches\n",
        "tinypkg-1.0.dist-info/METADATA": b"Metadata-Version: 2.1\nName: tinypkg\nVersion: 1.0\n",
        "tinypkg-1.0.dist-info/WHEEL": b"Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\nTag: py3-none-any\n",
    }
    record = io.StringIO()
    writer = csv.writer(record, lineterminator="\n")
    for name, data in files.items():
        writer.writerow([name, _hash(data), len(data)])
    writer.writerow(["tinypkg-1.0.dist-info/RECORD", "", ""])
    wheel = folder / "tinypkg-1.0-py3-none-any.whl"
    with zipfile.ZipFile(wheel, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in files.items():
            zf.writestr(name, data)
        zf.writestr("tinypkg-1.0.dist-info/RECORD", record.getvalue())
    return wheel


def _trim(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(TOOLS / "trim_wheel.py"), *args], capture_output=True, text=True)


def test_trim_wheel_removes_files_and_their_record_lines_and_pip_installs_it(tmp_path):
    wheel = _tiny_wheel(tmp_path)
    out = tmp_path / "out"
    done = _trim(str(wheel), str(out), "--drop", "tinypkg/data/*", "--keep", "tinypkg/data/keep.txt")
    assert done.returncode == 0, done.stderr
    assert "removed 2 files" in done.stdout
    trimmed = out / wheel.name
    with zipfile.ZipFile(trimmed) as zf:
        names = set(zf.namelist())
        rows = list(csv.reader(io.StringIO(zf.read("tinypkg-1.0.dist-info/RECORD").decode())))
        for path, digest, size in rows:
            if path.endswith("/RECORD"):
                assert digest == size == ""
            else:
                data = zf.read(path)
                assert (digest, size) == (_hash(data), str(len(data))), path
        note = zf.read("tinypkg-1.0.dist-info/TRIMMED").decode()
    assert "tinypkg/data/big.bin" not in names and "tinypkg/data/sub/other.bin" not in names
    assert {"tinypkg/__init__.py", "tinypkg/data/keep.txt", "tinypkg/extra.txt"} <= names
    recorded = {row[0] for row in rows}
    assert recorded == names, "RECORD lists exactly the archive's files"
    assert "tinypkg/data/big.bin" in note and "--keep tinypkg/data/keep.txt" in note

    target = tmp_path / "site"
    pip = subprocess.run(
        [sys.executable, "-m", "pip", "install", "-q", "--disable-pip-version-check", "--no-index", "--no-deps", "--target", str(target), str(trimmed)],
        capture_output=True,
        text=True,
    )
    assert pip.returncode == 0, pip.stderr
    assert (target / "tinypkg" / "data" / "keep.txt").read_text() == "needed\n"
    assert not (target / "tinypkg" / "data" / "big.bin").exists()
    installed_record = (target / "tinypkg-1.0.dist-info" / "RECORD").read_text()
    assert "big.bin" not in installed_record


def test_trim_wheel_refuses_a_keep_rule_that_matches_nothing(tmp_path):
    wheel = _tiny_wheel(tmp_path)
    done = _trim(str(wheel), str(tmp_path / "out"), "--drop", "tinypkg/data/*", "--keep", "tinypkg/data/missing.txt")
    assert done.returncode != 0
    assert "matches nothing" in done.stderr


def _bash(*args: str, timeout: int) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHON": sys.executable}
    return subprocess.run(["bash", str(TOOLS / "gpu_bundle.sh"), *args], capture_output=True, text=True, env=env, timeout=timeout)


@pytest.mark.slow
def test_bundle_for_this_python_fits_two_parts_and_installs_offline(tmp_path):
    out = tmp_path / "bundle"
    built = _bash("build", "--python-version", "host", "--out", str(out), timeout=600)
    assert built.returncode == 0, built.stdout + built.stderr

    parts = sorted(out.glob(f"{BUNDLE}.part*.tar"))
    assert 1 <= len(parts) <= 2, parts
    for part in parts:
        assert part.stat().st_size <= PART_LIMIT, f"{part.name}: {part.stat().st_size} bytes"

    members: dict[str, int] = {}
    part_of: dict[str, Path] = {}
    for part in parts:
        with tarfile.open(part) as tar:
            names = tar.getnames()
            assert f"{BUNDLE}/install.sh" in names and f"{BUNDLE}/MANIFEST.txt" in names, part.name
            for member in tar.getmembers():
                if member.isfile():
                    members[member.name] = member.size
                    part_of[member.name] = part
            manifest = tar.extractfile(f"{BUNDLE}/MANIFEST.txt").read().decode()
    listed = {line.split()[3]: int(line.split()[1]) for line in manifest.splitlines() if line and not line.startswith("#")}
    for path, size in listed.items():
        assert members.get(f"{BUNDLE}/{path}") == size, path
    assert any(path.startswith("tests/") for path in listed)

    (ms_wheel,) = [name for name in members if name.startswith(f"{BUNDLE}/wheels/mani_skill-3.0.1")]
    with tarfile.open(part_of[ms_wheel]) as tar:
        with zipfile.ZipFile(io.BytesIO(tar.extractfile(ms_wheel).read())) as zf:
            names = set(zf.namelist())
    assert "mani_skill/assets/robots/panda/panda_v2.urdf" in names
    assert "mani_skill/assets/robots/panda/panda_v3.urdf" in names
    assert "mani_skill/assets/robots/panda/realsense2_description/meshes/d415.stl" in names
    assert "mani_skill/utils/scene_builder/table/assets/table.glb" in names
    assert not any(n.startswith("mani_skill/assets/environment_maps/") for n in names)
    assert not any(n.startswith("mani_skill/assets/robots/fetch/") for n in names)
    assert "mani_skill-3.0.1.dist-info/TRIMMED" in names

    checked = _bash("check-install", str(out), timeout=600)
    output = checked.stdout + checked.stderr
    assert checked.returncode == 0, output[-6000:]
    assert "mani_skill_space 0.1.0" in output
    assert "made, reset and stepped SampleCollection-v1" in output
    assert "made, reset and stepped PickCube-v1" in output
    assert "all from the bundle, the declared packages or the standard library" in output
    assert "gpu_bundle: check-install OK" in output
