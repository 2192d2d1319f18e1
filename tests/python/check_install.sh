#!/bin/sh
# SPDX-License-Identifier: GPL-3.0-or-later
# The Python client installs as a package, offline, with the system's pip and setuptools
# (clients/python/pyproject.toml), and the installed module is the one imported.
# Usage: check_install.sh PYTHON SOURCE_DIR WORKDIR
set -eu
python=$1 source=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
cp -r "$source/clients/python" "$work/src"  # pip builds in place: keep the tree clean
"$python" -m pip install --quiet --no-index --no-build-isolation --no-deps --target "$work/site" \
  "$work/src"
installed=$(cd "$work" && PYTHONPATH="$work/site" "$python" -c \
  'import sphles_client; print(sphles_client.__file__)')
case "$installed" in
  "$work/site/"*) echo "installed: $installed" ;;
  *) echo "imported $installed, not the installed package" >&2; exit 1 ;;
esac
PYTHONPATH="$work/site" "$python" -c 'from sphles_client import Client, ApiError; Client("http://127.0.0.1:1")'
# The offline reader is installed beside it.
PYTHONPATH="$work/site" "$python" -c 'import sphles_run, sys; sys.exit(not sphles_run.__file__.startswith(sys.argv[1]))' "$work/site/"
