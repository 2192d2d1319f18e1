#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# Installs every Debian package sphles needs (build, tests, rendering, service, browser tests).
# Safe to re-run: does nothing when all packages are already installed.
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(
  build-essential cmake ninja-build pkg-config clang-format universal-ctags
  libeigen3-dev librandom123-dev libhdf5-dev libhdf5-openmpi-dev hdf5-tools libfftw3-dev libfftw3-mpi-dev
  libvtk9-dev libosmesa6-dev libopenmpi-dev openmpi-bin libpng-dev
  libavcodec-dev libavformat-dev libavutil-dev libswscale-dev
  libboost-dev libboost-system-dev nlohmann-json3-dev libcli11-dev libspdlog-dev libvalijson-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  chromium chromium-driver
  python3 python3-matplotlib python3-h5py python3-websocket python3-pip python3-setuptools
  paraview xvfb xauth qemu-user fonts-dejavu-core
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
else
  echo "setup: installing ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
  echo "setup: done"
fi

# ParaView's Python modules for pvbatch (the reader tests, docs/analysis.md). Debian's
# python3-paraview conflicts with python3-vtk9, which libvtk9-dev needs, so the package is
# unpacked into .deps/ (never installed) at the version of the installed paraview.
paraview_python=.deps/python3-paraview
if [ ! -d "$paraview_python/usr/lib/python3/dist-packages/paraview" ]; then
  version=$(dpkg-query -W -f='${Version}' paraview)
  echo "setup: unpacking python3-paraview $version into $paraview_python"
  rm -rf "$paraview_python" .deps/download
  mkdir -p .deps/download
  (cd .deps/download && { apt-get download -qq "python3-paraview=$version" 2> /dev/null ||
    { "${sudo_cmd[@]}" apt-get update -qq && apt-get download -qq "python3-paraview=$version"; }; })
  dpkg-deb -x .deps/download/python3-paraview_*.deb "$paraview_python"
  rm -rf .deps/download
fi
