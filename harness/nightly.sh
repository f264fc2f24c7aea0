#!/usr/bin/env bash
# The nightly cross-simulator check on the bundled scenes: sets up everything (harness/setup.sh),
# builds the `progmo` command, then runs `progmo check` and writes the report to out/check/.
# Extra arguments go to `progmo check` (e.g. scene files, --accept, --jobs N).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
bash harness/setup.sh
cargo build --release --bin progmo -q
exec ./target/release/progmo check "$@"
