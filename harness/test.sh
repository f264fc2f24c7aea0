#!/usr/bin/env bash
# Runs every test of progmo: the Rust core (cargo test) and the Python harness (pytest).
# On a fresh machine it first creates the environment (harness/setup.sh).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash harness/setup.sh
echo "== static checks: cargo fmt, clippy -D warnings, mypy, stubtest (the .pyi against the built extension) ==" >&2
for c in rustfmt clippy; do  # part of rustup's default profile; added if a toolchain lacks them
  cargo "${c/rustfmt/fmt}" --version >/dev/null 2>&1 || rustup component add "$c"
done
cargo fmt --all -- --check
cargo clippy --release --workspace --all-targets -q -- -D warnings
.venv/bin/python -m mypy
.venv/bin/python -m mypy.stubtest progmo._core --allowlist harness/stubtest-allowlist.txt
echo "== cargo test (Rust core, pure Rust) ==" >&2
# The robot scenes read example-robot-data's URDFs (installed by setup.sh): the same search path
# the Python package uses (progmo.data.robot_path).
PROGMO_ROBOT_PATH="$(.venv/bin/python -c 'import os; from progmo import data; print(os.pathsep.join(map(str, data.robot_path())))')"
export PROGMO_ROBOT_PATH
cargo test --release
echo "== headless Chromium for the report test ==" >&2
bash harness/install_chromium.sh || echo "warning: no headless Chromium: the report browser test will be skipped (and say so)" >&2
echo "== pytest (harness) ==" >&2
.venv/bin/python -m pytest -q tests/python
