#!/usr/bin/env bash
# Coverage-guided fuzzing of the scene loader, the expression compiler/evaluator and the robot
# file importers (URDF, MJCF: the bytes go through the scene loader's door, fuzzing::robot).
#
#   bash fuzz/run.sh [TARGET] [RUNS]     TARGET: scene | expr | urdf | mjcf | sweep | all (default
#                                        all), RUNS default 10^7
#   MAX_TIME=SECONDS bash fuzz/run.sh ...  also stop each target after SECONDS (libFuzzer
#                                        -max_total_time; the final stats give the executions)
#
# Needs the nightly toolchain (`rustup toolchain list`) and cargo-fuzz, installed here if missing.
# Seeds: references/scenes, tests/scenes, tests/bad_scenes (scene target); the quoted strings of
# those files (expr target); tests/robots, the catalog's robots/, example-robot-data's URDFs and
# MuJoCo's test models (urdf, mjcf targets; from $PROGMO_ROBOT_PATH, else the checkout's .venv of
# harness/setup.sh; files over -max_len also go in shrunk: comments, <visual> blocks and indentation
# removed), with the formats' dictionaries fuzz/dicts/{urdf,mjcf}.dict; the bundled sweep files
# (sweep target: fuzz/python/sweep_target.py, atheris, run by $PYTHON, default the checkout's
# .venv/bin/python, which needs `pip install atheris`; dictionary fuzz/dicts/sweep.dict). Targets
# that write a file per input use /dev/shm (a rewrite on disk costs milliseconds). One process, no
# -jobs/-workers: the machine is shared. libFuzzer prints
# the executions and the time at the end ("Done N runs in S second(s)"); crashes land in
# fuzz/artifacts/TARGET/ (reproduce: cargo +nightly fuzz run -O -a -s none TARGET fuzz/artifacts/TARGET/FILE).
# Build: release (-O) with debug assertions and overflow checks (-a: an integer overflow panics), no
# sanitizer (-s none: the crate has no unsafe code; about 3x the executions per second of the
# default AddressSanitizer build). `cargo test` runs a bounded version on stable
# (tests/fuzz_props.rs).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root/fuzz"
target="${1:-all}"
runs="${2:-10000000}"
limit=(-max_total_time="${MAX_TIME:-0}")
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz

seed() {
    mkdir -p seeds/scene seeds/expr seeds/sweep
    cp "$root"/references/sweeps/*.toml seeds/sweep/
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
    # Robot files: as they are, and shrunk to fit -max_len where they are longer.
    local share
    share="${PROGMO_ROBOT_PATH:-$(ls -d "$root"/.venv/lib/python3*/site-packages/cmeel.prefix/share 2>/dev/null | head -1 || true)}"
    python3 - "$root" "$share" <<'PY'
import pathlib, re, sys
root, share = pathlib.Path(sys.argv[1]), sys.argv[2]
out = {t: pathlib.Path("seeds") / t for t in ("urdf", "mjcf")}
for d in out.values():
    d.mkdir(parents=True, exist_ok=True)
files = {"urdf": list((root / "tests/robots").glob("*.urdf")) + list((root / "tests/bad_scenes/files").glob("*.urdf")),
         "mjcf": list((root / "tests/robots/mjcf").glob("*.xml")) + list((root / "references/scenes/robots").glob("*.xml"))}
if share:
    files["urdf"] += pathlib.Path(share, "example-robot-data").rglob("*.urdf")
    files["mjcf"] += pathlib.Path(share).parent.parent.glob("mujoco/testdata/*.xml")
for t, paths in files.items():
    for k, p in enumerate(sorted(set(paths))):
        b = p.read_bytes()
        (out[t] / f"{k:03}_{p.name}").write_bytes(b)
        if len(b) > 8192:
            s = re.sub(rb"<!--.*?-->", b"", b, flags=re.S)
            s = re.sub(rb"<visual\b.*?</visual>", b"", s, flags=re.S)
            s = re.sub(rb"\n\s+", b"\n", s)
            (out[t] / f"{k:03}_small_{p.name}").write_bytes(s[:8192])
PY
}

run() {
    local t="$1" dict=()
    mkdir -p "corpus/$t"
    [ -f "dicts/$t.dict" ] && dict=(-dict="dicts/$t.dict")
    cargo +nightly fuzz run -O -a -s none "$t" "corpus/$t" "seeds/$t" -- \
        -runs="$runs" -max_len=8192 -timeout=10 -rss_limit_mb=2048 \
        -print_final_stats=1 "${limit[@]}" "${dict[@]}"
}

run_sweep() {
    local py="${PYTHON:-$root/.venv/bin/python}"
    mkdir -p corpus/sweep artifacts/sweep
    "$py" -c "import atheris" 2>/dev/null || "$py" -m pip install -q atheris
    (cd artifacts/sweep && "$py" "$root/fuzz/python/sweep_target.py" "$root/fuzz/corpus/sweep" \
        "$root/fuzz/seeds/sweep" -dict="$root/fuzz/dicts/sweep.dict" -runs="$runs" -max_len=8192 \
        -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 "${limit[@]}")
}

seed
case "$target" in
    all) run scene; run expr; run urdf; run mjcf; run_sweep ;;
    sweep) run_sweep ;;
    *) run "$target" ;;
esac
