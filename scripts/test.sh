#!/usr/bin/env bash
# The test command: installs what is missing, then runs the whole test suite (unit, integration, MPI).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
cargo test "$@"
