#!/usr/bin/env bash
# Sets up, builds and runs every test. Exits non-zero if any step or test fails.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh -DSPHLES_WERROR=ON
cd build
ctest --output-on-failure --parallel "$(nproc)" --timeout 1200
