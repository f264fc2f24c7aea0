#!/usr/bin/env bash
# Runs every test of progmo: the Rust core (cargo test) and the Python harness (pytest).
# On a fresh machine it first creates the environment (harness/setup.sh).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
start=$SECONDS
phase() { echo "== [$(( (SECONDS - start) / 60 ))m$(( (SECONDS - start) % 60 ))s] $* ==" >&2; }
# The tests judge results, not speed: the release profile's whole-program LTO and single codegen
# unit (Cargo.toml: the shipped build) would make every release build of this run (the extension,
# the wheel, the test binaries) slower on 2 cores for the same results (no fast-math).
export CARGO_PROFILE_RELEASE_LTO=false CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16
phase "set-up (harness/setup.sh) beside cargo fmt --check and clippy -D warnings (functions <= 100 lines)"
for c in rustfmt clippy; do  # part of rustup's default profile; added if a toolchain lacks them
  cargo "${c/rustfmt/fmt}" --version >/dev/null 2>&1 || rustup component add "$c"
done
# The Rust checks need nothing of setup.sh: they run beside it, on the core its pip phase leaves
# idle (on a fresh clone set-up spends about a minute on one core: downloads and unpacking), and
# they build the proc-macros and build scripts its extension build would build. That build waits
# for them on cargo's build-directory lock.
rust_static_log="$(mktemp)"
( cargo fmt --all -- --check && cargo clippy --release --workspace --all-targets -q -- -D warnings ) \
  >"$rust_static_log" 2>&1 &
rust_static_pid=$!
bash harness/setup.sh
# The C++ anchor of `progmo bench` (g++ against the pin wheel's headers: about 5 min of one core)
# builds into its cache beside the Rust phases, which leave a core idle part of the time; the bench
# tests wait for it on the build's lock (anchor.build) and then find it built. A failure here is
# only reported: those tests build it again and say why.
anchor_log="$(mktemp)"
.venv/bin/python -c 'from progmo.bench import anchor; anchor.build()' >"$anchor_log" 2>&1 &
anchor_pid=$!
phase "static checks: cargo fmt and clippy's outcome, ruff (complexity <= 15), mypy, stubtest (the .pyi against the built extension)"
rust_static=0
wait "$rust_static_pid" || rust_static=$?
cat "$rust_static_log" >&2
rm -f "$rust_static_log"
if [ "$rust_static" != 0 ]; then
  echo "test.sh: FAILED: cargo fmt --check or cargo clippy -D warnings (its output is above)" >&2
  exit 1
fi
.venv/bin/ruff check -q harness/progmo tests/python fuzz/python
.venv/bin/python -m mypy
.venv/bin/python -m mypy.stubtest progmo._core --allowlist harness/stubtest-allowlist.txt
# Headless Chromium for the report test: network and dpkg bound, so it installs beside the checks
# (after setup.sh, whose Eigen install holds the same dpkg lock).
chromium_log="$(mktemp)"
bash harness/install_chromium.sh >"$chromium_log" 2>&1 &
chromium_pid=$!
phase "cargo test (Rust core, pure Rust) beside pytest (harness): its output follows pytest's"
# The robot scenes read example-robot-data's URDFs (installed by setup.sh): the same search path
# the Python package uses (progmo.data.robot_path).
PROGMO_ROBOT_PATH="$(.venv/bin/python -c 'import os; from progmo import data; print(os.pathsep.join(map(str, data.robot_path())))')"
export PROGMO_ROBOT_PATH
# Side by side (CI time): each phase leaves a core idle part of the time (rustc's serial front
# end and links; pytest's last files on one worker); the two together keep both busy.
# pytest's test_stdout.py runs target/release/progmo: built first (a link: the core's release
# build is the one `maturin develop` made for the extension, reused because the features resolve
# alike, Cargo.toml), then "ok" or "failed" goes into $PROGMO_BIN_READY, where those tests wait,
# and only then cargo test's own build (the unit tests' and integration tests' binaries: minutes).
cargo_log="$(mktemp)"
PROGMO_BIN_READY="$(mktemp -u)"
export PROGMO_BIN_READY
# The examples are not built here (clippy --all-targets above compiles them; rhs_profile was a
# 55-second unit of this build): the library, the binary, the integration tests, then the doctests.
tests=(--lib --bins --tests)
( if cargo build --release --bin progmo; then echo ok >"$PROGMO_BIN_READY"
  else echo failed >"$PROGMO_BIN_READY"; exit 1; fi
  cargo test --release "${tests[@]}" && cargo test --release --doc ) >"$cargo_log" 2>&1 &
cargo_pid=$!
phase "headless Chromium for the report test"
wait "$chromium_pid" || { cat "$chromium_log" >&2; echo "warning: no headless Chromium: the report browser test will be skipped (and say so)" >&2; }
rm -f "$chromium_log"
phase "pytest (harness; one worker per core, a test file per worker: pytest-xdist)"
py_status=0
# --timeout: a test still running after 30 min fails with every thread's stack (pytest-timeout)
# instead of holding the run until CI's own limit ends it with nothing said.
.venv/bin/python -m pytest -q -n "$(nproc)" --dist loadfile --durations=15 --timeout=1800 tests/python || py_status=$?
phase "the C++ anchor's background build (the bench tests waited for it on its lock)"
wait "$anchor_pid" || { echo "warning: the C++ anchor's background build failed (the bench tests built it again and reported why):" >&2; tail -5 "$anchor_log" >&2; }
rm -f "$anchor_log"
phase "cargo test's output"
cargo_status=0
wait "$cargo_pid" || cargo_status=$?
cat "$cargo_log"
rm -f "$cargo_log" "$PROGMO_BIN_READY"
if [ "$py_status" != 0 ] || [ "$cargo_status" != 0 ]; then
  echo "test.sh: FAILED: pytest exit $py_status, cargo test exit $cargo_status" >&2
  exit 1
fi
phase "done"
