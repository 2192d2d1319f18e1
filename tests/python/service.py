# SPDX-License-Identifier: GPL-3.0-or-later
"""A real `sphles serve` for the Python tests: on a free port, with its data directory in a
fresh work directory."""

import os
import re
import shutil
import subprocess
import sys


def start_server(binary, work, token=None, name="service"):
    """Starts `binary serve` on a free port with WORK/data as its data directory (WORK is
    emptied first) and its log in WORK/serve.log; (process, url, data directory)."""
    data = os.path.join(work, "data")
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    command = [binary, "serve", "--port", "0", "--data", data, "--threads", "1",
               "--log-level", "warn"]
    if token:
        command += ["--token", token]
    with open(os.path.join(work, "serve.log"), "w") as log:
        server = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=log, text=True)
    line = server.stdout.readline()
    match = re.search(r"listening on (http://\S+?)/?$", line.strip())
    if not match:
        server.kill()
        sys.exit(f"{name}: no 'listening on' line: {line!r}")
    return server, match.group(1), data


def stop_server(server):
    """SIGTERM, as a user's Ctrl-C: every run stops with a checkpoint, then the server."""
    server.terminate()
    server.wait(timeout=60)
