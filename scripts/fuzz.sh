#!/usr/bin/env bash
# Coverage-guided fuzzing of every parser that takes outside input (tests/fuzz, cargo-fuzz).
#
#   scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]
#
# Installs cargo-fuzz if missing (pinned), builds every target once (AddressSanitizer, debug
# assertions and overflow checks on), then runs each TARGET (default: all) for
# SECONDS_PER_TARGET seconds (default 10), one after the other, one process each. Prints per
# target the executions, executions per second and coverage (libFuzzer's final `cov:` edges
# and `ft:` features), and exits non-zero if any target found a crash, a timeout or an
# out-of-memory; the input is saved under tests/fuzz/artifacts/TARGET/.
#
# Environment: FUZZ_SANITIZER (address | none; default address), FUZZ_LOG_DIR (where each
# target's libFuzzer log goes; default tests/fuzz/target/fuzz-logs), FUZZ_ARGS (extra
# libFuzzer arguments), FUZZ_NO_BUILD (set: run the targets as last built, e.g. for a second
# run beside a first). Corpora grow in tests/fuzz/corpus/TARGET (ignored by git); the
# committed seeds in tests/fuzz/seeds/TARGET are read, never written. docs/fuzzing.md has the
# limits, the targets and the results.
set -euo pipefail
cd "$(dirname "$0")/.."

CARGO_FUZZ_VERSION=0.13.2
FUZZ_DIR=tests/fuzz
SECONDS_PER_TARGET="${1:-10}"
shift || true
SANITIZER="${FUZZ_SANITIZER:-address}"
LOG_DIR="${FUZZ_LOG_DIR:-$FUZZ_DIR/target/fuzz-logs}"
# The limits (see tests/fuzz/src/limits.rs, which enforces the allocation limit in-process).
RSS_LIMIT_MB=2048
MALLOC_LIMIT_MB=1024
TIMEOUT_S=10

if ! [[ "$SECONDS_PER_TARGET" =~ ^[0-9]+$ ]] || [ "$SECONDS_PER_TARGET" -lt 1 ]; then
    echo "usage: scripts/fuzz.sh [SECONDS_PER_TARGET] [TARGET...]" >&2
    exit 2
fi

# cargo-fuzz passes nightly -Z flags to rustc; RUSTC_BOOTSTRAP=1 lets the stable toolchain
# accept them (the stable toolchain ships the AddressSanitizer runtime).
export RUSTC_BOOTSTRAP=1

if ! cargo fuzz --version 2>/dev/null | grep -x "cargo-fuzz $CARGO_FUZZ_VERSION" >/dev/null; then
    echo "== installing cargo-fuzz $CARGO_FUZZ_VERSION"
    cargo install cargo-fuzz --version "$CARGO_FUZZ_VERSION" --locked
fi
if ! command -v c++ >/dev/null; then
    echo "libfuzzer-sys compiles libFuzzer's C++: install a C++ compiler (apt-get install g++)" >&2
    exit 2
fi

mapfile -t ALL < <(cargo fuzz list --fuzz-dir "$FUZZ_DIR")
if [ "$#" -gt 0 ]; then
    TARGETS=("$@")
    for t in "${TARGETS[@]}"; do
        # grep -x without -q reads all its input: with -q it may exit at the first match and
        # printf then dies of SIGPIPE, which pipefail reports as a failure.
        if ! printf '%s\n' "${ALL[@]}" | grep -x "$t" >/dev/null; then
            echo "unknown fuzz target '$t' (targets: ${ALL[*]})" >&2
            exit 2
        fi
    done
else
    TARGETS=("${ALL[@]}")
fi

# Larger inputs where the format needs them.
max_len() {
    case "$1" in
        tiff_file | tiff_structured) echo 65536 ;;
        region_query | scene_json | wire_decode | ome_metadata) echo 16384 ;;
        *) echo 4096 ;;
    esac
}

start=$(date +%s)
echo "== building ${#TARGETS[@]} fuzz target(s) (sanitizer: $SANITIZER)"
if [ -n "${FUZZ_NO_BUILD:-}" ]; then
    echo "FUZZ_NO_BUILD set: using the targets already built"
elif [ "${#TARGETS[@]}" -eq "${#ALL[@]}" ]; then
    cargo fuzz build --fuzz-dir "$FUZZ_DIR" -s "$SANITIZER"
else
    for t in "${TARGETS[@]}"; do
        cargo fuzz build --fuzz-dir "$FUZZ_DIR" -s "$SANITIZER" "$t"
    done
fi
built=$(date +%s)
echo "== built in $((built - start)) s"

BIN_DIR="$FUZZ_DIR/target/$(rustc -vV | sed -n 's/^host: //p')/release"
mkdir -p "$LOG_DIR"
failed=()
rows=()
for t in "${TARGETS[@]}"; do
    corpus="$FUZZ_DIR/corpus/$t"
    artifacts="$FUZZ_DIR/artifacts/$t"
    mkdir -p "$corpus" "$artifacts"
    dirs=("$corpus")
    [ -d "$FUZZ_DIR/seeds/$t" ] && dirs+=("$FUZZ_DIR/seeds/$t")
    dict=()
    [ -f "$FUZZ_DIR/dicts/$t.dict" ] && dict=("-dict=$FUZZ_DIR/dicts/$t.dict")
    log="$LOG_DIR/$t.log"
    echo "== $t: ${SECONDS_PER_TARGET} s"
    t0=$(date +%s)
    set +e
    # shellcheck disable=SC2086
    "$BIN_DIR/$t" "${dirs[@]}" "${dict[@]}" \
        -artifact_prefix="$artifacts/" \
        -max_total_time="$SECONDS_PER_TARGET" \
        -rss_limit_mb="$RSS_LIMIT_MB" \
        -malloc_limit_mb="$MALLOC_LIMIT_MB" \
        -timeout="$TIMEOUT_S" \
        -max_len="$(max_len "$t")" \
        -print_final_stats=1 \
        ${FUZZ_ARGS:-} >"$log" 2>&1
    rc=$?
    set -e
    t1=$(date +%s)
    stat() { sed -n "s/^stat::$1: *//p" "$log" | tail -1; }
    execs=$(stat number_of_executed_units)
    rate=$(stat average_exec_per_sec)
    last=$(grep -E '^#[0-9]+.*cov: ' "$log" | tail -1 || true)
    cov=$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$last")
    ft=$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$last")
    corp=$(sed -n 's/.* corp: \([0-9]*\).*/\1/p' <<<"$last")
    status=ok
    if [ "$rc" -ne 0 ]; then
        status="FAILED (exit $rc)"
        failed+=("$t")
        echo "-- $t failed; the end of its log ($log):"
        tail -40 "$log"
        ls -1 "$artifacts" | sed "s|^|   artifact: $artifacts/|"
    fi
    rows+=("$(printf '%-16s %6s %12s %9s %7s %7s %6s  %s' "$t" "$((t1 - t0))" \
        "${execs:-?}" "${rate:-?}" "${cov:-?}" "${ft:-?}" "${corp:-?}" "$status")")
done

end=$(date +%s)
echo
printf '%-16s %6s %12s %9s %7s %7s %6s  %s\n' target secs executions exec/s cov ft corpus status
printf '%s\n' "${rows[@]}"
echo "total wall time: $((end - start)) s (build $((built - start)) s), $(date -u +%FT%TZ), $(nproc) cores"
if [ "${#failed[@]}" -gt 0 ]; then
    echo "fuzzing found problems in: ${failed[*]}" >&2
    exit 1
fi
