#!/usr/bin/env bash
# mani-skill-space developer entry point. Sets everything up (idempotent, quick when already done), then:
#   bash run.sh main [args]   run the main job: the oracle and random policies on the smoke suite
#                             (python -m mani_skill_space.eval --suite smoke --policy oracle random)
#   bash run.sh test [args]   run the test suite (pytest, in two worker processes: pytest-xdist's -n 2;
#                             -n 0 runs it in one)
#   bash run.sh setup         only set up
# Setup: system packages on Debian 12 (python3-venv; the software Vulkan driver only when SAPIEN finds no
# rendering device), a .venv with the pinned stack (constraints.txt) and this package in editable mode.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
ROOT=$PWD
VENV="$ROOT/.venv"
PY="$VENV/bin/python"
STAMP="$VENV/.mani-skill-space-setup"

log() { printf '[setup] %s\n' "$*" >&2; }

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"
    elif command -v sudo >/dev/null 2>&1; then sudo "$@"
    else log "need root to run: $*"; exit 1
    fi
}

apt_install() {
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null
}

ensure_python() {
    if ! python3 -c 'import sys, venv, ensurepip; assert sys.version_info >= (3, 10)' 2>/dev/null; then
        log "installing python3-venv"
        as_root apt-get update -qq
        apt_install python3 python3-venv python3-dev
    fi
}

setup_hash() {
    cat setup.cfg pyproject.toml constraints.txt run.sh | sha256sum | cut -d' ' -f1
}

ensure_venv() {
    local wanted
    wanted=$(setup_hash)
    if [ -x "$PY" ] && [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$wanted" ]; then
        return
    fi
    [ -x "$PY" ] || { log "creating $VENV"; python3 -m venv "$VENV"; }
    log "installing the pinned Python stack (constraints.txt) and mani-skill-space (editable)"
    "$PY" -m pip install -q --upgrade pip
    "$PY" -m pip install -q -c constraints.txt "torch==2.13.0"
    "$PY" -m pip install -q -c constraints.txt -e ".[test]"
    echo "$wanted" > "$STAMP"
}

sapien_can_render() {
    "$PY" -c 'import sapien.render; sapien.render.RenderMaterial()' >/dev/null 2>&1
}

debian_mirror() {
    local uri
    uri=$(grep -hs '^URIs:' /etc/apt/sources.list.d/debian.sources | awk '{print $2}' | grep -v security | head -n1 || true)
    [ -n "$uri" ] || uri=$(grep -hs '^deb ' /etc/apt/sources.list | awk '{print $2}' | grep -v security | head -n1 || true)
    echo "${uri:-http://deb.debian.org/debian}"
}

ensure_vulkan() {
    sapien_can_render && return
    if ! grep -qs 'VERSION_CODENAME=bookworm' /etc/os-release; then
        log "SAPIEN finds no rendering device. Install a Vulkan driver (Mesa >= 24 lavapipe on CPU-only machines)."
        exit 1
    fi
    log "SAPIEN finds no rendering device: installing Mesa's software Vulkan driver from bookworm-backports"
    as_root tee /etc/apt/sources.list.d/mani-skill-space-backports.sources >/dev/null <<SOURCES
Types: deb
URIs: $(debian_mirror)
Suites: bookworm-backports
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
SOURCES
    as_root apt-get update -qq
    apt_install libvulkan1
    apt_install -t bookworm-backports mesa-vulkan-drivers
    sapien_can_render || { log "SAPIEN still finds no rendering device"; exit 1; }
}

setup() {
    ensure_python
    ensure_venv
    ensure_vulkan
}

command=${1:-main}
[ $# -gt 0 ] && shift
case "$command" in
    setup) setup ;;
    main) setup; exec "$PY" -m mani_skill_space.eval --suite smoke --policy oracle random "$@" ;;
    test) setup; exec "$PY" -m pytest -n 2 --dist loadgroup "$@" ;;
    *) echo "usage: bash run.sh [main|test|setup] [args...]" >&2; exit 2 ;;
esac
