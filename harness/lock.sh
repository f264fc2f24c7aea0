#!/usr/bin/env bash
# Rewrites harness/constraints.txt from the current .venv (after upgrading a dependency within the
# ranges of pyproject.toml): the nightly check and CI install exactly these versions.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
{
  sed -n '1,3p' harness/constraints.txt
  .venv/bin/python -m pip freeze | grep -v '^progmo\|^-e\|^#'
} > harness/constraints.txt.new
mv harness/constraints.txt.new harness/constraints.txt
echo "lock: wrote harness/constraints.txt ($(grep -vc '^#' harness/constraints.txt) packages)" >&2
