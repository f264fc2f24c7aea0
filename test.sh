#!/usr/bin/env bash
# Runs every test of progmo (the README's test command). Installs nothing by hand: cargo fetches crates.
set -euo pipefail
cd "$(dirname "$0")"
cargo test --release --all-targets
