#!/usr/bin/env bash
# Installs every Debian package sphles needs (build, tests, rendering, service, browser tests).
# Safe to re-run: does nothing when all packages are already installed.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config clang-format
  libeigen3-dev libhdf5-dev hdf5-tools libfftw3-dev
  libvtk9-dev libosmesa6-dev libopenmpi-dev libpng-dev
  libboost-dev libboost-system-dev nlohmann-json3-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  chromium chromium-driver
  python3 python3-matplotlib
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then sudo_cmd=(sudo); fi

# npm for the dashboard's plotting library (web/) and the browser test (tests/e2e/). The
# machine's Node.js (nodesource build) bundles npm; Debian's npm package conflicts with that
# Node.js, so it is never installed next to it: a bundled npm that is not on PATH is linked,
# else corepack (bundled with Node.js) provides npm from the npm registry. Only a machine with
# no Node.js at all gets Debian's nodejs and npm.
if ! command -v npm > /dev/null 2>&1; then
  if [ -x /usr/lib/node_modules/npm/bin/npm-cli.js ]; then
    echo "setup: linking the npm bundled with Node.js into /usr/local/bin"
    "${sudo_cmd[@]}" ln -sf /usr/lib/node_modules/npm/bin/npm-cli.js /usr/local/bin/npm
  elif command -v corepack > /dev/null 2>&1; then
    echo "setup: enabling npm through corepack"
    "${sudo_cmd[@]}" corepack enable npm
  elif ! command -v node > /dev/null 2>&1; then
    missing+=(nodejs npm)
  else
    echo "setup: node $(node --version) has no npm and no corepack; install npm for it" >&2
    exit 1
  fi
fi

if [ ${#missing[@]} -eq 0 ]; then
  echo "setup: all ${#packages[@]} packages present"
  exit 0
fi

echo "setup: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${sudo_cmd[@]}" apt-get update -qq
"${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
echo "setup: done"
