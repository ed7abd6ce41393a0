#!/usr/bin/env bash
# Prepares runs of benchmarks/device/vdi.sh and benchmarks/device/server.sh on the lent GPU
# machine (the `device` tool), which reaches nothing outside it and takes at most 64 MiB of
# working tree: run this here first.
#
#   bash benchmarks/device/prepare.sh
#
# Builds the release binaries, strips and gzips `viewer`, `ingest` and `brickserver` into
# .gpu-bin/ (about 25 MB), downloads the Vulkan loader packages the GPU machine lacks into
# .gl/, and the server bench's client and peer (Debian's wrk and nginx, with the libraries
# that machine may lack) into .srv/, and has git ignore all three (.git/info/exclude).
# NVIDIA's Vulkan driver needs glvnd's libraries beside the loader. Then, with the device tool:
#
#   run(command="bash benchmarks/device/vdi.sh", carry=[".gpu-bin", ".gl"], timeout_s=540)
#   run(command="bash benchmarks/device/server.sh", carry=[".gpu-bin", ".srv"], timeout_s=540)
set -euo pipefail
cd "$(dirname "$0")/../.."

cargo build --release --workspace --bins
mkdir -p .gpu-bin
for exe in viewer ingest brickserver; do
    strip -o ".gpu-bin/$exe" "target/release/$exe"
    gzip -f -9 ".gpu-bin/$exe"
done
for dir in /.gpu-bin/ /.gl/ /.srv/; do
    grep -qxF "$dir" .git/info/exclude 2>/dev/null || echo "$dir" >> .git/info/exclude
done
# download DIR PACKAGE...: the packages' amd64 .debs into DIR, unless DIR holds the first's;
# the package lists are fetched once, by the first download that needs them.
o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
lists=""
download() {
    local dir=$1
    shift
    if ! ls "$dir/$1"_*.deb >/dev/null 2>&1; then
        mkdir -p "$dir" /tmp/amd64/partial
        # shellcheck disable=SC2086
        [ -n "$lists" ] || { apt-get $o update && lists=1; }
        # shellcheck disable=SC2086
        (cd "$dir" && apt-get $o download "$@")
    fi
}
download .gl libglvnd0 libvulkan1 libegl1 libgl1 libglx0 libopengl0 libgles2
download .srv wrk libluajit-5.1-2 nginx libpcre2-8-0 libssl3
du -sh .gpu-bin .gl .srv
