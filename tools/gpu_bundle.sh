#!/usr/bin/env bash
# The offline bundle for a GPU run of mani_skill_space on a machine with no internet: the wheels it lacks, a
# trimmed mani-skill, our own wheel, the repo's tests/ and an install.sh, packed in at most two tar parts of at most
# 64 MiB each (the device tool carries 64 MiB a call).
#
#   bash tools/gpu_bundle.sh build [--python-version 3.12|host] [--out DIR] [--target-has device|torch]
#                                  [--part-limit BYTES] [--physx-gpu FILE]
#   bash tools/gpu_bundle.sh check-install [--numpy-wheel FILE] BUNDLE_DIR_OR_PARTS...
#
# build
#   Downloads (pip download --only-binary=:all: --no-deps, for CPython X.Y on manylinux x86_64) every package of the
#   table below that the target lacks, at the versions pinned in constraints.txt; repacks mani-skill without the
#   assets mani_skill_space never loads (tools/trim_wheel.py, rules in MANI_SKILL_TRIM below); builds our wheel from
#   the working tree as it is; adds tests/ and setup.cfg (pytest's markers), install.sh, BUNDLE_INFO and MANIFEST.txt;
#   packs it all into DIR/mani_skill_space_gpu_bundle.part1.tar (and .part2.tar only when one part cannot hold it),
#   each <= --part-limit (default 64 MiB = 67108864 bytes); fails loudly when two parts cannot hold it.
#   --python-version: 3.12 by default (the GPU machine's); "host" means this interpreter's (so that CI can install
#   it here, see check-install).
#   --target-has: what the target already has (the bundle leaves it out and install.sh checks that it imports):
#     device (default): the GPU machine's image as the device docs list it (torch, numpy, scipy, opencv, matplotlib,
#       pillow, h5py, lxml, requests, pytest, huggingface_hub, ... see the table's last column);
#     torch: only torch and numpy (and torch's own requirements). ManiSkill then needs opencv (48 MiB: import
#       mani_skill imports cv2) and scipy (34 MiB) besides sapien (49 MiB): about 200 MiB in all, more than two parts
#       hold, so this fails, loudly (with a larger --part-limit it builds, and check-install passes on it).
#   Each part travels to the device with the working tree, which counts in the same 64 MiB: the parts are balanced
#   (each file into the emptier part), so part1 holds sapien's wheel alone (49 MiB) and the rest goes to part2.
#   --physx-gpu FILE: SAPIEN's PhysX GPU library (linux-so.zip of github.com/sapien-sim/physx-precompiled, release
#     105.1-physx-5.3.1.patch0 for sapien 3.0.3, or the libPhysXGpu_64.so in it). SAPIEN downloads it on the first
#     physx.enable_gpu() into ~/.sapien/physx/<version>/, which an offline machine cannot: install.sh puts it there.
#     Without it the bundle still installs, and install.sh says that GPU PhysX needs that file.
#   PYTHON (environment): the interpreter that runs pip and the helpers; the repo's .venv by default, else python3.
#
# check-install
#   Proves on this (CPU) machine that a host-Python bundle installs and works offline with nothing but what the
#   target is declared to have: extracts the parts, makes a fresh venv (--without-pip: no site-packages of ours; the
#   bundle's own pip wheel installs), and exposes to it, through one .pth file, only the declared packages (BUNDLE_INFO's
#   TARGET_HAS import names, e.g. torch and numpy) and the closure of their own requirements, as symlinks to this
#   interpreter's copies; a package that pip installed there brings its requirements, so the target has those too.
#   Then runs the bundle's install.sh into a fresh --target folder, and with PYTHONPATH=that folder, from an empty
#   folder and a fresh asset cache: imports mani_skill_space, checks that every module loaded came from the bundle, the
#   declared packages or the standard library, makes SampleCollection-v1 (panda and panda_wristcam) and the bench peers
#   PickCube-v1 and PegInsertionSide-v1 with obs_mode="state", resets and steps them; then runs the bundle's GPU tests
#   the way install.sh says (pytest -m gpu tests/gpu: they skip without CUDA) when tests/gpu is in the bundle.
#   --numpy-wheel FILE: expose this numpy wheel instead of this interpreter's numpy (e.g. a numpy 2 wheel, as the GPU
#   machine has numpy 2.5).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ -z "${PYTHON:-}" ]; then
    if [ -x "$REPO/.venv/bin/python" ]; then PYTHON="$REPO/.venv/bin/python"; else PYTHON=python3; fi
fi
BUNDLE_NAME=mani_skill_space_gpu_bundle
DEFAULT_PART_LIMIT=67108864

die() { echo "gpu_bundle: error: $*" >&2; exit 1; }
log() { echo "gpu_bundle: $*" >&2; }

# Every package the GPU path imports, beyond torch, numpy and torch's own requirements (typing-extensions, filelock,
# fsspec, networkx, sympy, jinja2, setuptools): found by importing mani_skill_space, making our envs and the bench
# peers, and running tests/gpu in a venv with nothing else (check-install), and from the packages' METADATA.
# Columns: distribution (as in constraints.txt) | import name (what install.sh checks on the target) |
# on the GPU machine's image (its documented package list, read 2026-11-17): yes = left out with --target-has device |
# why.
PACKAGES="
sapien                 sapien            no   the simulator
mani-skill             mani_skill        no   ManiSkill (trimmed, see MANI_SKILL_TRIM)
gymnasium              gymnasium         no   env registry (gym.make)
Farama-Notifications   farama_notifications no gymnasium
cloudpickle            cloudpickle       yes  gymnasium
trimesh                trimesh           no   our procgen, ManiSkill, sapien's URDF loader
manifold3d             manifold3d        no   our procgen (trimesh booleans)
coacd                  coacd             no   our convex decompositions (assets with collision 'coacd')
tyro                   tyro              no   our CLIs (bench_gpu.py)
docstring_parser       docstring_parser  no   tyro
typeguard              typeguard         no   tyro
dacite                 dacite            no   ManiSkill (sapien_env)
defusedxml             defusedxml        no   ManiSkill (MJCF loader)
transforms3d           transforms3d      no   ManiSkill, sapien
pytorch-kinematics     pytorch_kinematics no  ManiSkill (pd_ee_pose controllers)
arm_pytorch_utilities  arm_pytorch_utilities no pytorch-kinematics
pytorch-seed           pytorch_seed      no   pytorch-kinematics
ipython                IPython           no   ManiSkill (utils.visualization imports IPython.display)
traitlets              traitlets         no   IPython
Pygments               pygments          yes  IPython, pytest
scipy                  scipy             yes  ManiSkill, our procgen
opencv-python-headless cv2               yes  ManiSkill (digital twin envs import cv2 at import mani_skill)
lxml                   lxml              yes  sapien's URDF loader, pytorch-kinematics
requests               requests          yes  sapien.physx
urllib3                urllib3           yes  requests
idna                   idna              yes  requests
certifi                certifi           yes  requests
charset-normalizer     charset_normalizer yes requests
tqdm                   tqdm              yes  ManiSkill, ours
ImageIO                imageio           yes  ManiSkill, ours
pillow                 PIL               yes  imageio, trimesh, matplotlib
matplotlib             matplotlib        yes  ManiSkill, pytorch-kinematics
contourpy              contourpy         yes  matplotlib
cycler                 cycler            yes  matplotlib
fonttools              fontTools         yes  matplotlib
kiwisolver             kiwisolver        yes  matplotlib
pyparsing              pyparsing         yes  matplotlib
python-dateutil        dateutil          yes  matplotlib
packaging              packaging         yes  matplotlib, pytest, huggingface_hub
absl-py                absl              yes  pytorch-kinematics
PyYAML                 yaml              yes  pytorch-kinematics, huggingface_hub
huggingface_hub        huggingface_hub   yes  ManiSkill (utils.download_asset)
h5py                   h5py              yes  ManiSkill's RecordEpisode, our demonstrations
pytest                 pytest            yes  the GPU tests
iniconfig              iniconfig         yes  pytest
pluggy                 pluggy            yes  pytest
"
# The requirements of packages above that the device image has with theirs (huggingface_hub's httpx2 and co.,
# python-dateutil's tzdata): --target-has torch adds them.
TORCH_TARGET_EXTRA="httpx2 httpcore2 h11 anyio truststore hf-xet click tzdata"

# What mani_skill_space never loads from mani-skill 3.0.1 (tools/trim_wheel.py rules, the last match decides).
# Our envs and the bench peers use the panda and panda_wristcam agents only (envs/base.py SUPPORTED_ROBOTS): Panda loads
# robots/panda/panda_v2.urdf (+ .srdf) and franka_description's meshes, PandaWristCam panda_v3.urdf, which also
# loads realsense2_description/meshes/d415.stl (and nothing else of realsense2_description). Other robots' folders
# are only read when their agent is built. No Python code of mani-skill reads assets/environment_maps,
# assets/maniskill2-scene-2.glb or utils/building/assets/floor_tiles_06_diff_2k_aligned.png; the ReplicaCAD sky
# (autumn_field_puresky_4k.hdr) is only read by ReplicaCAD scenes. Kept: all code, the partnet_mobility metadata
# (read at import), the table scene (PickCube-v1, PegInsertionSide-v1), the ground's grid textures.
MANI_SKILL_TRIM=(
    --drop 'mani_skill/assets/environment_maps/*'
    --drop 'mani_skill/assets/maniskill2-scene-2.glb'
    --drop 'mani_skill/assets/robots/*'
    --keep 'mani_skill/assets/robots/panda/*'
    --drop 'mani_skill/assets/robots/panda/realsense2_description/*'
    --drop 'mani_skill/assets/robots/panda/sciurus17_description/*'
    --keep 'mani_skill/assets/robots/panda/realsense2_description/meshes/d415.stl'
    --drop 'mani_skill/utils/scene_builder/replicacad/autumn_field_puresky_4k.hdr'
    --drop 'mani_skill/utils/building/assets/floor_tiles_06_diff_2k_aligned.png'
    --keep 'mani_skill/assets/robots/panda/panda_v2.urdf'
    --keep 'mani_skill/assets/robots/panda/panda_v3.urdf'
    --keep 'mani_skill/utils/scene_builder/table/assets/table.glb'
)

# pip, less the warnings of this machine's pip configuration about local index folders it lacks.
pip_() { "$PYTHON" -m pip --disable-pip-version-check "$@" 2> >(grep -v "^WARNING: Location 'file:" >&2); }

host_python_version() { "$PYTHON" -c 'import sys; print("%d.%d" % sys.version_info[:2])'; }

# pins NAME...: NAME==VERSION for each, from constraints.txt (names compared the PEP 503 way), one a line.
pins() {
    "$PYTHON" - "$REPO/constraints.txt" "$@" <<'PY'
import re, sys
norm = lambda s: re.sub(r"[-_.]+", "-", s).lower()
pinned = {}
for line in open(sys.argv[1]):
    line = line.split("#", 1)[0].strip()
    if "==" in line:
        n, v = line.split("==", 1)
        pinned[norm(n)] = f"{n.strip()}=={v.strip()}"
missing = [n for n in sys.argv[2:] if norm(n) not in pinned]
if missing:
    sys.exit(f"gpu_bundle: error: not pinned in constraints.txt: {' '.join(missing)}")
print("\n".join(pinned[norm(n)] for n in sys.argv[2:]))
PY
}

# Files of the working tree (tracked, and untracked ones git does not ignore) under the given paths, NUL-separated.
tree_files() {
    (cd "$REPO" && git ls-files -z --cached --others --exclude-standard -- "$@" \
        | xargs -0 -r sh -c 'for f; do if [ -e "$f" ]; then printf "%s\0" "$f"; fi; done' sh)
}

cmd_build() {
    local pyver=3.12 out="$REPO/dist/gpu_bundle" target_has=device part_limit=$DEFAULT_PART_LIMIT physx=""
    while [ $# -gt 0 ]; do
        case "$1" in
            --python-version) pyver="${2:?--python-version needs a value}"; shift 2 ;;
            --out) out="${2:?--out needs a value}"; shift 2 ;;
            --target-has) target_has="${2:?--target-has needs a value}"; shift 2 ;;
            --part-limit) part_limit="${2:?--part-limit needs a value}"; shift 2 ;;
            --physx-gpu) physx="${2:?--physx-gpu needs a value}"; shift 2 ;;
            *) die "build: unknown argument $1" ;;
        esac
    done
    [ "$pyver" = host ] && pyver="$(host_python_version)"
    [[ "$pyver" =~ ^3\.[0-9]+$ ]] || die "--python-version must be 3.N or host, not $pyver"
    case "$target_has" in device|torch) ;; *) die "--target-has must be device or torch" ;; esac
    [[ "$part_limit" =~ ^[0-9]+$ ]] || die "--part-limit must be a number of bytes"
    [ -z "$physx" ] || [ -f "$physx" ] || die "--physx-gpu: no file $physx"

    local work stage
    work="$(mktemp -d "${TMPDIR:-/tmp}/gpu_bundle_build.XXXXXX")"
    CLEANUP="$work"
    trap 'rm -rf "$CLEANUP"' EXIT
    stage="$work/$BUNDLE_NAME"
    mkdir -p "$stage/wheels" "$stage/pip" "$work/download" "$work/src"

    # What to download, and what the target is declared to have.
    local names=() specs=() target_has_imports="torch numpy" name import device why
    while read -r name import device why; do
        [ -n "$name" ] || continue
        if [ "$target_has" = device ] && [ "$device" = yes ]; then
            target_has_imports+=" $import"
        else
            names+=("$name")
        fi
    done <<< "$PACKAGES"
    # shellcheck disable=SC2206
    [ "$target_has" = torch ] && names+=($TORCH_TARGET_EXTRA)
    mapfile -t specs < <(pins "${names[@]}")
    [ ${#specs[@]} -eq ${#names[@]} ] || die "could not pin every package (see above)"
    log "downloading ${#specs[@]} wheels for CPython $pyver (target has: $target_has)"
    pip_ download -q --only-binary=:all: --no-deps \
        --python-version "$pyver" --implementation cp \
        --platform manylinux2014_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux_2_28_x86_64 \
        -d "$work/download" "${specs[@]}"

    local ms
    ms="$(ls "$work"/download/mani_skill-*.whl)"
    "$PYTHON" "$REPO/tools/trim_wheel.py" "$ms" "$stage/wheels" "${MANI_SKILL_TRIM[@]}" >&2
    rm "$ms"
    mv "$work"/download/*.whl "$stage/wheels/"

    # Our wheel, from a copy of the working tree as it is (tracked and untracked files git does not ignore), so that
    # the build leaves nothing in the repo.
    tree_files mani_skill_space assets tasks setup.py setup.cfg pyproject.toml README.md MANIFEST.in \
        | tar -c -C "$REPO" --null -T - -f - | tar -x -C "$work/src"
    local isolation=(--no-build-isolation)
    "$PYTHON" -c 'import setuptools' 2>/dev/null || isolation=()
    pip_ wheel -q --no-deps "${isolation[@]}" -w "$stage/wheels" "$work/src" >&2
    ls "$stage"/wheels/mani_skill_space-*.whl >/dev/null || die "our wheel was not built"

    # pip itself, for a target whose python has no pip (install.sh runs it from the wheel).
    pip_ download -q --only-binary=:all: --no-deps -d "$stage/pip" \
        "pip==$("$PYTHON" -m pip --version | awk '{print $2}')"

    # The tests as they are now, and setup.cfg for pytest's configuration (markers).
    tree_files tests | tar -c -C "$REPO" --null -T - -f - | tar -x -C "$stage"
    cp "$REPO/setup.cfg" "$stage/setup.cfg"
    if [ -n "$physx" ]; then mkdir -p "$stage/physx" && cp "$physx" "$stage/physx/"; fi

    cat > "$stage/BUNDLE_INFO" <<EOF
# sourced by install.sh
BUNDLE_PYTHON=$pyver
BUNDLE_TARGET_HAS=$target_has
TARGET_HAS="$target_has_imports"
EOF
    write_install_sh "$stage/install.sh"
    chmod +x "$stage/install.sh"

    mkdir -p "$out"
    rm -f "$out/$BUNDLE_NAME".part*.tar
    "$PYTHON" - "$work" "$BUNDLE_NAME" "$out" "$part_limit" "$pyver" "$target_has" <<'PY'
"""Pack the staged bundle into at most two tar parts, each self-contained (install.sh, BUNDLE_INFO and MANIFEST.txt in
each), balancing them (each item into the emptier part) so that the larger part is as small as it can be."""
import hashlib, os, sys, tarfile
from pathlib import Path

work, name, out, limit, pyver, target_has = Path(sys.argv[1]), sys.argv[2], Path(sys.argv[3]), int(sys.argv[4]), sys.argv[5], sys.argv[6]
stage = work / name
COMMON = ["install.sh", "BUNDLE_INFO", "MANIFEST.txt"]
RESERVE = 64 * 1024  # tar's end blocks, record padding, the common files


def tar_cost(path: Path) -> int:
    files = [p for p in path.rglob("*") if p.is_file()] if path.is_dir() else [path]
    return sum(1536 + -(-p.stat().st_size // 512) * 512 for p in files)


items = []  # (cost, relative path); tests/ travels as one item
for entry in sorted(stage.iterdir()):
    if entry.name in COMMON:
        continue
    if entry.name in ("wheels", "pip", "physx"):
        items += [(tar_cost(p), p.relative_to(stage)) for p in sorted(entry.iterdir())]
    else:
        items.append((tar_cost(entry), entry.relative_to(stage)))
items.sort(key=lambda item: -item[0])
total = sum(cost for cost, _ in items)
parts = [[]] if total + RESERVE <= limit else [[], []]
loads = [0] * len(parts)
for cost, rel in items:
    fits = [i for i in range(len(parts)) if loads[i] + cost + RESERVE <= limit]
    if not fits:
        table = "\n".join(f"  {c / 2**20:8.1f} MiB  {r}" for c, r in items)
        sys.exit(
            f"gpu_bundle: error: the bundle ({total / 2**20:.1f} MiB) does not fit in two parts of {limit / 2**20:.1f} MiB "
            f"(could not place {rel}, {cost / 2**20:.1f} MiB; parts hold {', '.join(f'{l / 2**20:.1f}' for l in loads)} MiB).\n"
            f"Items:\n{table}\n"
            + ("With --target-has torch every dependency travels; the GPU machine's image has most of them: use --target-has device." if target_has == "torch" else "")
        )
    best = min(fits, key=lambda i: loads[i])
    parts[best].append(rel)
    loads[best] += cost


def sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


part_names = [f"{name}.part{i + 1}.tar" for i in range(len(parts))]
lines = [
    f"# {name}: CPython {pyver}, target has: {target_has}; {len(parts)} part(s); extract every part into one folder:",
    "#   for p in " + " ".join(part_names) + "; do tar -xf $p; done; bash " + name + "/install.sh TARGET_DIR",
    "# part  bytes  sha256  path",
]
for i, part in enumerate(parts):
    for rel in sorted(part):
        path = stage / rel
        files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
        for p in files:
            lines.append(f"{i + 1}  {p.stat().st_size}  {sha256(p)}  {p.relative_to(stage)}")
(stage / "MANIFEST.txt").write_text("\n".join(lines) + "\n")

out.mkdir(parents=True, exist_ok=True)
for i, part in enumerate(parts):
    target = out / part_names[i]
    with tarfile.open(target, "w", format=tarfile.GNU_FORMAT) as tar:
        for rel in COMMON + sorted(str(r) for r in part):
            tar.add(stage / rel, arcname=f"{name}/{rel}")
    size = target.stat().st_size
    if size > limit:
        sys.exit(f"gpu_bundle: error: {target} is {size} bytes, over the limit {limit}")
    print(f"{target}  {size} bytes ({size / 2**20:.1f} MiB)")
PY
    log "manifest: $out (MANIFEST.txt inside each part)"
}

write_install_sh() {
    cat > "$1" <<'INSTALL'
#!/usr/bin/env bash
# Installs this offline bundle of mani_skill_space for a GPU run:  bash install.sh TARGET_DIR
# (PYTHON=... picks the interpreter; python3 by default.) Extract every part into one folder first.
#
# All wheels go into TARGET_DIR with `pip install --no-index --no-deps --target`, not into the interpreter's
# site-packages nor a venv: the machine's own torch, numpy (and, per BUNDLE_INFO, its other packages) stay the ones
# used, nothing of the machine's is upgraded or removed, and PYTHONPATH=TARGET_DIR puts the bundle first. (A venv made
# with --system-site-packages would do the same, but needs the venv module, which some Pythons lack.)
# Without pip on the machine, pip runs from the bundled pip wheel.
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
[ $# -eq 1 ] || { echo "usage: bash $0 TARGET_DIR" >&2; exit 2; }
TARGET="$(mkdir -p "$1" && cd "$1" && pwd)"
PY="${PYTHON:-python3}"
# shellcheck source=/dev/null
. "$HERE/BUNDLE_INFO"
fail() { echo "install.sh: error: $*" >&2; exit 1; }

have="$("$PY" -c 'import sys; print("%d.%d" % sys.version_info[:2])')" || fail "no python at $PY"
[ "$have" = "$BUNDLE_PYTHON" ] || fail "this bundle's wheels are for Python $BUNDLE_PYTHON; $PY is $have (set PYTHON=...)"

# Every file of every part is here?
missing=$(cd "$HERE" && awk '!/^#/ && NF == 4 { print $1, $4 }' MANIFEST.txt | while read -r part path; do [ -f "$path" ] || echo "  $path (part $part)"; done)
[ -z "$missing" ] || fail "files missing (extract every part into one folder):
$missing"
if command -v sha256sum >/dev/null; then
    (cd "$HERE" && awk '!/^#/ && NF == 4 { print $3 "  " $4 }' MANIFEST.txt | sha256sum -c --quiet -) \
        || fail "files differ from MANIFEST.txt (a part damaged in transfer?)"
fi

# What the bundle leaves to the machine.
absent=""
for module in $TARGET_HAS; do
    "$PY" -c "import $module" >/dev/null 2>&1 || absent+=" $module"
done
[ -z "$absent" ] || fail "this bundle expects the machine to have (import names):$absent (bundle built with --target-has $BUNDLE_TARGET_HAS)"

if "$PY" -m pip --version >/dev/null 2>&1; then
    PIP=("$PY" -m pip)
else
    PIP=("$PY" "$(ls "$HERE"/pip/pip-*.whl | head -n 1)/pip")
fi
"${PIP[@]}" install -q --disable-pip-version-check --no-cache-dir --no-index --find-links "$HERE/wheels" --no-deps \
    --upgrade --target "$TARGET" "$HERE"/wheels/*.whl

# SAPIEN's PhysX GPU library: physx.enable_gpu() downloads it into ~/.sapien/physx/<version>/ unless it is there.
physx_version="$(cd / && PYTHONPATH="$TARGET" "$PY" -c 'import sapien.physx as p; print(p.version())')"
physx_dir="$HOME/.sapien/physx/$physx_version"
supplied="$(ls "$HERE"/physx/* 2>/dev/null | head -n 1 || true)"
if [ -n "$supplied" ]; then
    mkdir -p "$physx_dir"
    case "$supplied" in
        *.zip) "$PY" -c 'import sys, zipfile; zipfile.ZipFile(sys.argv[1]).extractall(sys.argv[2])' "$supplied" "$physx_dir" ;;
        *) cp "$supplied" "$physx_dir/libPhysXGpu_64.so" ;;
    esac
fi
if [ -f "$physx_dir/libPhysXGpu_64.so" ]; then
    physx_note="SAPIEN's PhysX GPU library: $physx_dir/libPhysXGpu_64.so"
else
    physx_note="WARNING: no $physx_dir/libPhysXGpu_64.so: SAPIEN's GPU PhysX (sim_backend=physx_cuda) will try to download it
  (linux-so.zip of the release $physx_version of github.com/sapien-sim/physx-precompiled) and fail offline; copy it
  there, or rebuild the bundle with --physx-gpu FILE. CPU simulation does not need it."
fi

cat <<EOF
install.sh: installed $(ls "$HERE"/wheels/*.whl | wc -l) wheels into $TARGET (Python $have).
$physx_note
Run (from the bundle folder, which holds tests/ and setup.cfg; not from a checkout of the repo, whose
mani_skill_space/ folder would shadow the installed package):
  cd $HERE
  PYTHONPATH=$TARGET $PY -m pytest -m gpu tests/gpu
  PYTHONPATH=$TARGET $PY tests/gpu/bench_gpu.py
EOF
INSTALL
}

# Resolve BUNDLE_DIR_OR_PARTS into an extracted bundle folder under $1; prints its path.
extract_bundle() {
    local into="$1"; shift
    local parts=() arg
    for arg in "$@"; do
        if [ -d "$arg" ] && [ -f "$arg/install.sh" ]; then echo "$(cd "$arg" && pwd)"; return; fi
        if [ -d "$arg" ]; then
            local found=("$arg"/$BUNDLE_NAME.part*.tar)
            [ -e "${found[0]}" ] || die "no $BUNDLE_NAME.part*.tar in $arg"
            parts+=("${found[@]}")
        elif [ -f "$arg" ]; then parts+=("$arg")
        else die "no such bundle, folder or part: $arg"; fi
    done
    [ ${#parts[@]} -gt 0 ] || die "check-install: give the bundle folder or its parts"
    for arg in "${parts[@]}"; do tar -xf "$arg" -C "$into"; done
    echo "$into/$BUNDLE_NAME"
}

cmd_check_install() {
    local numpy_wheel="" args=()
    while [ $# -gt 0 ]; do
        case "$1" in
            --numpy-wheel) numpy_wheel="${2:?--numpy-wheel needs a file}"; shift 2 ;;
            *) args+=("$1"); shift ;;
        esac
    done
    [ ${#args[@]} -gt 0 ] || die "usage: check-install [--numpy-wheel FILE] BUNDLE_DIR_OR_PARTS..."
    local tmp bundle
    tmp="$(mktemp -d "${TMPDIR:-/tmp}/gpu_bundle_check.XXXXXX")"
    CLEANUP="$tmp"
    trap 'rm -rf "$CLEANUP"' EXIT
    mkdir -p "$tmp/extracted" "$tmp/shim" "$tmp/empty" "$tmp/cache"
    bundle="$(extract_bundle "$tmp/extracted" "${args[@]}")"
    # shellcheck source=/dev/null
    . "$bundle/BUNDLE_INFO"
    [ "$(host_python_version)" = "$BUNDLE_PYTHON" ] || die "the bundle is for Python $BUNDLE_PYTHON; this machine's $PYTHON is $(host_python_version) (build it with --python-version host)"

    # A fresh venv of the same base interpreter, without pip and without any site-packages of ours.
    local base
    base="$("$PYTHON" -c 'import sys; print(sys._base_executable)')"
    "$base" -m venv --without-pip "$tmp/venv"
    local fresh="$tmp/venv/bin/python" site
    site="$("$fresh" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"

    # The shim: what the target is declared to have (TARGET_HAS, import names) and their requirements' closure,
    # symlinked from this interpreter's site-packages.
    (cd "$tmp/empty" && "$PYTHON" - "$tmp/shim" "$numpy_wheel" $TARGET_HAS) <<'PY'
import importlib.metadata as md, os, re, sys
from pathlib import Path
from packaging.requirements import Requirement

shim, numpy_wheel, modules = Path(sys.argv[1]), sys.argv[2], sys.argv[3:]
norm = lambda s: re.sub(r"[-_.]+", "-", s).lower()
providers = md.packages_distributions()
todo = []
for module in modules:
    if module not in providers:
        sys.exit(f"gpu_bundle: check-install needs {module} here (the target is declared to have it)")
    todo += providers[module]
seen, linked = set(), []
while todo:
    name = norm(todo.pop())
    if name in seen:
        continue
    seen.add(name)
    if name == "numpy" and numpy_wheel:
        continue
    try:
        dist = md.distribution(name)
    except md.PackageNotFoundError:
        continue  # an optional or platform-specific requirement not installed here
    for requirement in dist.requires or []:
        req = Requirement(requirement)
        if req.marker is None or req.marker.evaluate({"extra": ""}):
            todo.append(req.name)
    tops = {Path(str(f)).parts[0] for f in dist.files or [] if not str(f).startswith("..")}
    for top in sorted(tops - {"__pycache__"}):
        source = Path(dist.locate_file(top))
        if source.exists() and not (shim / top).exists():
            os.symlink(source, shim / top)
    linked.append(f"{dist.metadata['Name']} {dist.version}")
print("gpu_bundle: check-install: the target is emulated with " + ", ".join(sorted(linked)), file=sys.stderr)
PY
    if [ -n "$numpy_wheel" ]; then
        pip_ install -q --no-deps --no-index --target "$tmp/shim" "$numpy_wheel"
    fi
    echo "$tmp/shim" > "$site/_gpu_bundle_check_target_has.pth"

    PYTHON="$fresh" bash "$bundle/install.sh" "$tmp/site"

    log "check-install: importing and making envs from the fresh install"
    (cd "$tmp/empty" && MANI_SKILL_SPACE_CACHE="$tmp/cache" PYTHONPATH="$tmp/site" "$fresh" - "$tmp/site" "$tmp/shim" <<'PY'
import sys, sysconfig
from pathlib import Path

site, shim = Path(sys.argv[1]).resolve(), Path(sys.argv[2])
import gymnasium as gym
import mani_skill
import numpy
import sapien
import torch

import mani_skill_space

for module in (mani_skill_space, mani_skill, sapien, gym):
    assert Path(module.__file__).resolve().is_relative_to(site), f"{module.__name__} from {module.__file__}, not the bundle"
for module in (torch, numpy):
    assert Path(module.__file__).is_relative_to(shim), f"{module.__name__} from {module.__file__}"
assert (site / "mani_skill-3.0.1.dist-info" / "TRIMMED").is_file(), "mani-skill is not the trimmed wheel"
print(f"mani_skill_space {mani_skill_space.__version__} (mani_skill {mani_skill.__version__}, sapien {sapien.__version__}, "
      f"gymnasium {gym.__version__}; torch {torch.__version__}, numpy {numpy.__version__}); ENV_IDS: {', '.join(mani_skill_space.ENV_IDS)}")

cases = [
    ("SampleCollection-v1", {}),
    ("SampleCollection-v1", {"robot_uids": "panda_wristcam"}),
    ("PickCube-v1", {}),
    ("PegInsertionSide-v1", {}),
]
for env_id, kwargs in cases:
    env = gym.make(env_id, obs_mode="state", **kwargs)
    obs, _ = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert obs.shape[-1] > 0
    env.close()
    print("made, reset and stepped", env_id, kwargs or "")

allowed = [site, shim, Path(sysconfig.get_paths()["stdlib"]).resolve(), Path(sysconfig.get_paths()["platstdlib"]).resolve()]
strays = sorted(
    {f"{name}: {module.__file__}" for name, module in list(sys.modules.items())
     if isinstance(getattr(module, "__file__", None), str) and Path(module.__file__).is_absolute()
     and not any(Path(module.__file__).is_relative_to(a) or Path(module.__file__).resolve().is_relative_to(a) for a in allowed)}
)
assert not strays, "modules from outside the bundle and the declared packages:\n" + "\n".join(strays)
print("check-install: OK:", len(sys.modules), "modules, all from the bundle, the declared packages or the standard library")
PY
    )
    if [ -d "$bundle/tests/gpu" ]; then
        log "check-install: pytest -m gpu tests/gpu in the bundle folder (skips without CUDA)"
        (cd "$bundle" && MANI_SKILL_SPACE_CACHE="$tmp/cache" PYTHONPATH="$tmp/site" "$fresh" -m pytest -q -p no:cacheprovider -m gpu tests/gpu) \
            || die "pytest -m gpu tests/gpu failed in the fresh install"
    fi
    if [ -f "$bundle/tests/gpu/bench_gpu.py" ]; then
        (cd "$bundle" && PYTHONPATH="$tmp/site" "$fresh" tests/gpu/bench_gpu.py --help >/dev/null) \
            || die "tests/gpu/bench_gpu.py --help failed in the fresh install"
        log "check-install: tests/gpu/bench_gpu.py --help runs"
    fi
    echo "gpu_bundle: check-install OK"
}

case "${1:-}" in
    build) shift; cmd_build "$@" ;;
    check-install) shift; cmd_check_install "$@" ;;
    *) sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//' >&2; exit 2 ;;
esac
