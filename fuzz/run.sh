#!/usr/bin/env bash
# Coverage-guided fuzzing of the scene loader and the expression compiler/evaluator.
#
#   bash fuzz/run.sh [TARGET] [RUNS]     TARGET: scene | expr | all (default all), RUNS default 10^7
#
# Needs the nightly toolchain (`rustup toolchain list`) and cargo-fuzz, installed here if missing.
# Seeds: references/scenes, tests/scenes, tests/bad_scenes (scene target); the quoted strings of
# those files (expr target). One process, no -jobs/-workers: the machine is shared. libFuzzer prints
# the executions and the time at the end ("Done N runs in S second(s)"); crashes land in
# fuzz/artifacts/TARGET/ (reproduce: cargo +nightly fuzz run -O -s none TARGET fuzz/artifacts/TARGET/FILE).
# Build: release (-O), no sanitizer (-s none: the crate has no unsafe code; about 3x the executions
# per second of the default AddressSanitizer build). `cargo test` runs a bounded version on stable
# (tests/fuzz_props.rs).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root/fuzz"
target="${1:-all}"
runs="${2:-10000000}"
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz

seed() {
    mkdir -p seeds/scene seeds/expr
    cp "$root"/references/scenes/*.toml "$root"/tests/scenes/*.toml seeds/scene/
    find "$root"/tests/bad_scenes -name '*.toml' -exec cp {} seeds/scene/ \;
    # One file per quoted string of the scene files (rows, forces, parameters, mass entries).
    for f in seeds/scene/*.toml; do
        local k=0
        grep -o '"[^"]*"' "$f" | tr -d '"' | while IFS= read -r s; do
            k=$((k + 1))
            printf '%s' "$s" > "seeds/expr/$(basename "$f" .toml)_$k"
        done
    done
}

run() {
    local t="$1"
    mkdir -p "corpus/$t"
    cargo +nightly fuzz run -O -s none "$t" "corpus/$t" "seeds/$t" -- \
        -runs="$runs" -max_len=8192 -timeout=10 -rss_limit_mb=2048 \
        -print_final_stats=1
}

seed
case "$target" in
    all) run scene; run expr ;;
    *) run "$target" ;;
esac
