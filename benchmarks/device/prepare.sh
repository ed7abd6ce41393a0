#!/usr/bin/env bash
# Prepares a run of benchmarks/device/vdi.sh on the lent GPU machine (the `device` tool), which
# reaches nothing outside it and takes at most 64 MiB of working tree: run this here first.
#
#   bash benchmarks/device/prepare.sh
#
# Builds the release binaries, strips and gzips `viewer` and `ingest` into .gpu-bin/ (about
# 20 MB), downloads the Vulkan loader packages the GPU machine lacks into .gl/, and has git
# ignore both (.git/info/exclude). NVIDIA's Vulkan driver needs glvnd's libraries beside the
# loader. Then, with the device tool:
#
#   run(command="bash benchmarks/device/vdi.sh", carry=[".gpu-bin", ".gl"], timeout_s=540)
set -euo pipefail
cd "$(dirname "$0")/../.."

cargo build --release --workspace --bins
mkdir -p .gpu-bin
for exe in viewer ingest; do
    strip -o ".gpu-bin/$exe" "target/release/$exe"
    gzip -f -9 ".gpu-bin/$exe"
done
for dir in /.gpu-bin/ /.gl/; do
    grep -qxF "$dir" .git/info/exclude 2>/dev/null || echo "$dir" >> .git/info/exclude
done
if ! ls .gl/libglvnd0_*.deb >/dev/null 2>&1; then
    mkdir -p .gl /tmp/amd64/partial
    o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    # shellcheck disable=SC2086
    apt-get $o update
    # shellcheck disable=SC2086
    (cd .gl && apt-get $o download libvulkan1 libglvnd0 libegl1 libgl1 libglx0 libopengl0 libgles2)
fi
du -sh .gpu-bin .gl
