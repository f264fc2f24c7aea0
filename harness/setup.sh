#!/usr/bin/env bash
# Prepares everything the harness needs on a fresh machine, idempotently:
#   .venv with numpy, scipy, MuJoCo, Pinocchio, Drake, matplotlib, mcap, pytest (the ranges of
#   pyproject.toml, at the locked versions of harness/constraints.txt) and the Rust core built
#   into it as the package progmo (maturin develop, release);
#   Eigen's headers for the C++ anchor of `progmo bench` (apt-get install libeigen3-dev when
#   missing, as root or with passwordless sudo; without them the bench skips the anchor and says why).
# Run by harness/nightly.sh and harness/test.sh; prints what it does, fails loudly.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
py="${PYTHON:-python3}"
if [ ! -x .venv/bin/python ]; then
  echo "setup: creating .venv with $($py --version)" >&2
  "$py" -m venv .venv
fi
stamp=.venv/.progmo-deps
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ harness/constraints.txt -nt "$stamp" ]; then
  echo "setup: installing Python dependencies (first run: about a minute)" >&2
  .venv/bin/python -m pip install -q --upgrade pip
  # One list of requirements: pyproject.toml (build-system, dependencies, the `test` and `drake`
  # extras: the nightly check runs all three simulators).
  mapfile -t reqs < <(.venv/bin/python - <<'PY'
import tomllib
with open("pyproject.toml", "rb") as f:
    d = tomllib.load(f)
print("\n".join(d["build-system"]["requires"] + d["project"]["dependencies"]
                + d["project"]["optional-dependencies"]["test"]
                + d["project"]["optional-dependencies"]["drake"]))
PY
)
  .venv/bin/python -m pip install -q -c harness/constraints.txt "${reqs[@]}"
  touch "$stamp"
fi
echo "setup: building the Rust core into .venv (maturin develop --release)" >&2
( . .venv/bin/activate && maturin develop --release -q >/dev/null ) || {
  echo "setup: error: building the Python extension failed (run 'maturin develop --release' in .venv for details)" >&2
  exit 1
}
bash harness/progmo/bench/cpp/install_eigen.sh >/dev/null \
  || echo "setup: warning: no Eigen headers: progmo bench will skip its C++ anchor (and say so)" >&2
