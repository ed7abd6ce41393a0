#!/usr/bin/env bash
# Installs what building and testing Residency needs on a fresh Debian machine, idempotently:
# Debian packages (compiler, Python venv, Mesa's lavapipe Vulkan driver, Xvfb), and a Python virtual environment in .venv with the
# external clients the tests use (zarr-python, ome-zarr-models, tifffile, ...).
# Source it or run it; it does nothing that is already done.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

need_apt=()
command -v cc >/dev/null 2>&1 || need_apt+=(build-essential)
# libFuzzer (cargo fuzz, scripts/fuzz.sh) is C++.
command -v g++ >/dev/null 2>&1 || need_apt+=(g++)
command -v pkg-config >/dev/null 2>&1 || need_apt+=(pkg-config)
python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || need_apt+=(python3-venv)
# Vulkan on the CPU (Mesa lavapipe) for the viewer where there is no GPU, Xvfb for the window test.
ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 || need_apt+=(mesa-vulkan-drivers libvulkan1)
command -v Xvfb >/dev/null 2>&1 || need_apt+=(xvfb)
if [ ${#need_apt[@]} -gt 0 ]; then
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "${need_apt[@]}"
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "cargo not found: install Rust (https://rustup.rs) and re-run" >&2
  exit 1
fi

stamp=.venv/.requirements.sha
want=$(sha256sum scripts/python-requirements.txt | cut -d' ' -f1)
if [ ! -x .venv/bin/python ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  python3 -m venv .venv
  .venv/bin/pip install -q --upgrade pip
  .venv/bin/pip install -q -r scripts/python-requirements.txt
  echo "$want" > "$stamp"
fi
