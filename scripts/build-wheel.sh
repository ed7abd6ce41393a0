#!/usr/bin/env bash
# Builds the `residency` wheel (python/pyproject.toml, by maturin) into target/wheels (numpy's
# wheel, its one dependency, into target/wheels/deps): the three
# programs installed on the PATH, the web viewer under ENV/share/residency/web (where
# `brickserver` looks), and the Python package `residency` (python/residency, over the extension
# module python/src/lib.rs). Needs scripts/setup.sh's environment (maturin is in .venv).
#
#   bash scripts/build-wheel.sh        # -> target/wheels/residency-VERSION-cp310-abi3-PLATFORM.whl
#
# The programs are stripped of debug information (the release profile keeps line tables for
# backtraces; a user's install need not carry them). The platform tag is the manylinux one of
# the newest glibc symbol version any of the three programs needs (maturin checks
# the extension module against it), so pip refuses the wheel on
# an older system instead of failing at run time. Idempotent: everything is rebuilt from the
# current tree, and the wheel replaces an earlier one of the same name.
set -euo pipefail
cd "$(dirname "$0")/.."

cargo build --release --workspace --bins
bash scripts/build-web.sh >/dev/null

stage=python/wheel-data
rm -rf "$stage"
mkdir -p "$stage/scripts" "$stage/data/share/residency"
for program in ingest brickserver viewer; do
  strip --strip-debug -o "$stage/scripts/$program" "target/release/$program"
done
cp -r target/release/web "$stage/data/share/residency/web"

# The newest GLIBC_x.y any program needs. maturin checks the extension module against the same
# tag (its auditwheel check fails the build if the module needs a newer symbol). The module is
# built by maturin alone: a separate `cargo build` of it would set pyo3's build environment
# differently, and each would rebuild pyo3 after the other.
glibc=$(for f in "$stage"/scripts/*; do objdump -T "$f"; done \
  | grep -o 'GLIBC_[0-9]*\.[0-9]*' | sort -t. -k2 -n -u | tail -1 | sed 's/GLIBC_//')
tag="manylinux_${glibc/./_}"
echo "== the programs need glibc $glibc or newer: platform tag $tag"

rm -f target/wheels/residency-*.whl
.venv/bin/maturin build --release --quiet -m python/Cargo.toml --out target/wheels \
  --compatibility "$tag" --strip
wheel=$(ls target/wheels/residency-*.whl)
echo "== $wheel ($(du -h "$wheel" | cut -f1))"

# The wheel's one dependency, numpy, at the test environment's version, beside it: the wheel's
# test installs both into a fresh environment without the package index.
numpy=$(.venv/bin/python -c 'import numpy; print(numpy.__version__)')
.venv/bin/pip download -q --only-binary :all: --no-deps -d target/wheels/deps "numpy==$numpy"
