#!/usr/bin/env bash
# Installs what building and testing Residency needs on a fresh Debian machine, idempotently:
# Debian packages (compiler, clang for the web build's C, Python venv, Mesa's lavapipe Vulkan driver, Xvfb, Chromium, Node.js), a Python virtual environment in
# .venv with the external clients the tests use (zarr-python, ome-zarr-models, tifffile, neuroglancer, ...), and the browser tests'
# npm packages in tests/browser/node_modules.
# Source it or run it; it does nothing that is already done.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

need_apt=()
command -v cc >/dev/null 2>&1 || need_apt+=(build-essential)
# libFuzzer (cargo fuzz, scripts/fuzz.sh) is C++.
command -v g++ >/dev/null 2>&1 || need_apt+=(g++)
command -v pkg-config >/dev/null 2>&1 || need_apt+=(pkg-config)
# The web build compiles zstd's C (zstd-sys, the VDIs' `shuffled_zstd`) to WebAssembly: clang.
command -v clang >/dev/null 2>&1 || need_apt+=(clang)
python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || need_apt+=(python3-venv)
# Vulkan on the CPU (Mesa lavapipe) for the viewer where there is no GPU, Xvfb for the window test.
ls /usr/share/vulkan/icd.d/lvp_icd*.json >/dev/null 2>&1 || need_apt+=(mesa-vulkan-drivers libvulkan1)
command -v Xvfb >/dev/null 2>&1 || need_apt+=(xvfb)
# The browser tests: Debian's Chromium (headless, WebGPU on its SwiftShader adapter), Node.js.
[ -x /usr/bin/chromium ] || need_apt+=(chromium)
command -v npm >/dev/null 2>&1 || need_apt+=(nodejs npm)
if [ ${#need_apt[@]} -gt 0 ]; then
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -q
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q "${need_apt[@]}"
fi

if ! command -v cargo >/dev/null 2>&1; then
  echo "cargo not found: install Rust (https://rustup.rs) and re-run" >&2
  exit 1
fi

# The test environment comes from the lock (exact versions of every package, transitive ones
# included); scripts/python-requirements.txt is the human list the lock is made from (the lock's
# header says how). The stamp is the lock's hash, so a changed lock reinstalls.
stamp=.venv/.requirements.sha
want=$(sha256sum scripts/python-requirements.lock | cut -d' ' -f1)
if [ ! -x .venv/bin/python ] || [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  python3 -m venv .venv
  .venv/bin/pip install -q --upgrade pip
  .venv/bin/pip install -q -r scripts/python-requirements.lock
  echo "$want" > "$stamp"
fi

# The browser tests (tests/browser, tests/python/support/browser.py) drive Debian's Chromium with
# playwright-core, which needs Node.js 20 or newer. Debian 12's own nodejs is 18: where `node` is
# older than 20, a Node.js 22 binary comes from the npm registry (package node-linux-ARCH) into
# tests/browser/.node, and the tests use it.
node_major() { "$1" -e 'console.log(process.versions.node.split(".")[0])' 2>/dev/null || echo 0; }
if [ "$(node_major node)" -lt 20 ]; then
  arch=$(uname -m | sed 's/^x86_64$/x64/; s/^aarch64$/arm64/')
  node_bin=tests/browser/.node/node_modules/node-linux-$arch/bin
  if [ "$(node_major "$node_bin/node")" -lt 20 ]; then
    echo "== node $(node --version 2>/dev/null || echo missing) is older than 20: installing Node.js 22 into tests/browser/.node"
    mkdir -p tests/browser/.node
    npm install --prefix tests/browser/.node --no-save --no-package-lock --no-audit --no-fund --loglevel=error "node-linux-$arch@22"
  fi
  PATH="$PWD/$node_bin:$PATH"
fi

# tests/browser/node_modules from package-lock.json: playwright-core (no browser download: the
# tests use Debian's Chromium), esbuild, and Viv (@hms-dbmi/viv) with deck.gl, luma.gl and React
# for the Viv page. The neuroglancer client comes with the `neuroglancer` Python package.
stamp=tests/browser/node_modules/.package-lock.sha
want=$(sha256sum tests/browser/package-lock.json | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "== npm ci in tests/browser"
  (cd tests/browser && npm ci --no-audit --no-fund --loglevel=error)
  echo "$want" > "$stamp"
fi
