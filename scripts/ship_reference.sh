#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Copies what a reference run's users need from a `sphles reference` run directory into
# data/reference/NAME: scene.json, run.json, timeseries.csv and spectra/ (E(k, t) as CSV). The
# checkpoints, slices and frames stay behind (hundreds of MiB at 256³).
#   scripts/ship_reference.sh RUN_DIR NAME
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -eq 2 ] || { echo "usage: $0 RUN_DIR NAME" >&2; exit 2; }
run=$1
dest=data/reference/$2
for f in scene.json run.json timeseries.csv spectra/index.csv; do
  [ -f "$run/$f" ] || { echo "$0: '$run' has no $f: not a reference run" >&2; exit 2; }
done
grep -q '"kind": "reference"' "$run/run.json" ||
  { echo "$0: '$run/run.json' is not a reference run's" >&2; exit 2; }
rm -rf "$dest"
mkdir -p "$dest/spectra"
cp "$run/scene.json" "$run/run.json" "$run/timeseries.csv" "$dest/"
cp "$run"/spectra/*.csv "$dest/spectra/"
du -sh "$dest"
