#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Sets up, builds and starts the sphles service with the default case running: the 3D
# Taylor-Green vortex of SPEC §6.1 at Re = 1600 (scenes/tgv3d-re1600.json: 32³, WC4, D_K = 8Δl,
# t ∈ [0, 15], from a glass), shown beside its DNS and the spectral reference sphles ships, with
# live ω² and |τ_SFS| slices at x = π. Open the URL it prints ("sphles serve: listening on http://127.0.0.1:8080/")
# for the dashboard; Ctrl-C (or SIGTERM) checkpoints the run and stops. Runs live in runs/service/
# and survive restarts: resume them from the dashboard or with POST /api/runs/{id}/resume.
# Extra arguments go to `sphles serve`, e.g. --port 9000, --token SECRET, --bind 0.0.0.0,
# --max-running 2, --set particles_per_side=24 (docs/api.md, README "The service").
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh
echo "run.sh: starting the service; open the dashboard at the URL below (Ctrl-C stops it)"
exec build/app/sphles serve --data runs/service --start-run scenes/tgv3d-re1600.json \
  --set 'render.fields=["omega2","tau_sfs"]' "$@"
