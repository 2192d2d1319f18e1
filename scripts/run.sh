#!/usr/bin/env bash
# Sets up, builds and runs the default case: the 3D Taylor-Green vortex of SPEC §6.1 at 32³
# (WC4, D_K = 8Δl), printing progress and writing runs/tgv3d/{scene.json,timeseries.csv}.
# Extra arguments go to `sphles run`, e.g. --set particles_per_side=48 --threads 2.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh
exec build/app/sphles run scenes/tgv3d.json --out runs/tgv3d "$@"
