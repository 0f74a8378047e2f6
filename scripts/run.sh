#!/usr/bin/env bash
# The main job on its default configuration: installs what is missing, builds in release mode and runs.
# Extra arguments are passed on (PETSc options such as -snes_monitor go last).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
cargo build --release --quiet
exec target/release/mpm-concrete run configs/ct-demo.toml "$@"
