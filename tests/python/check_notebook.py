#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The Python examples against a real `sphles serve`: clients/python/examples/workflow.ipynb
(its code cells in order, as one script) with matplotlib and with matplotlib hidden, and
clients/python/examples/kernel_study.py with tiny settings.

Usage: check_notebook.py SPHLES_BINARY WORK_DIR. Exits non-zero with the failed check.
(check_notebook.py --exec NOTEBOOK SUMMARY.json [--hide-matplotlib] is the child that runs the
notebook.)"""

import json
import math
import os
import shutil
import subprocess
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
CLIENT = os.path.normpath(os.path.join(HERE, "..", "..", "clients", "python"))
EXAMPLES = os.path.join(CLIENT, "examples")
NOTEBOOK = os.path.join(EXAMPLES, "workflow.ipynb")
KERNELS = ["wendland_c4", "wendland_c6", "quintic_spline"]
HINT = "install python3-matplotlib to see the plots"


def check(condition, what):
    if not condition:
        sys.exit(f"check_notebook: FAILED: {what}")
    print(f"ok: {what}")


def execute(notebook, summary_path, hide_matplotlib):
    """Runs the notebook's code cells in order in one namespace, as Jupyter would, and writes
    what they left behind to SUMMARY.json."""
    if hide_matplotlib:
        # A None entry makes `import matplotlib` raise ImportError, as on a machine without it.
        sys.modules["matplotlib"] = None
        sys.modules["matplotlib.pyplot"] = None
    with open(notebook, encoding="utf-8") as f:
        cells = json.load(f)["cells"]
    namespace = {"__name__": "__main__"}
    for number, cell in enumerate(cells):
        if cell["cell_type"] == "code":
            exec(compile("".join(cell["source"]), f"{notebook} cell {number}", "exec"), namespace)
    offline = namespace["offline"]
    summary = {"run_id": namespace["run_id"], "saved": namespace["saved"],
               "plotted": namespace["plt"] is not None,
               "omega2_shape": list(namespace["omega2"].shape),
               "energy_sum": float(namespace["E"].sum() * (namespace["k"][1] - namespace["k"][0])),
               "reference_shells": int(namespace["reference_k"].size),
               "offline": offline.path if offline is not None else None}
    with open(summary_path, "w") as f:
        json.dump(summary, f)


def check_notebook_file():
    with open(NOTEBOOK, encoding="utf-8") as f:
        notebook = json.load(f)
    cells = notebook["cells"]
    check(notebook["nbformat"] == 4 and all(
        c["cell_type"] in ("markdown", "code") and isinstance(c["source"], list)
        and isinstance(c["metadata"], dict) and c.get("id") for c in cells),
        f"{os.path.basename(NOTEBOOK)}: nbformat 4, {len(cells)} cells")
    check(all(c["outputs"] == [] and c["execution_count"] is None
              for c in cells if c["cell_type"] == "code"), "no outputs stored")
    check("SPDX-License-Identifier: GPL-3.0-or-later" in "".join(cells[0]["source"]),
          "the first markdown cell holds the SPDX header")


def run_notebook(work, name, environment, hide_matplotlib):
    """The notebook in a child Python started in examples/, so that it finds the client the way
    a user's notebook next to it does; (stdout, summary)."""
    summary_path = os.path.join(work, name + ".json")
    command = [sys.executable, os.path.abspath(__file__), "--exec", NOTEBOOK, summary_path]
    if hide_matplotlib:
        command.append("--hide-matplotlib")
    environment = dict(os.environ, **environment)
    environment.pop("PYTHONPATH", None)
    result = subprocess.run(command, cwd=EXAMPLES, env=environment, capture_output=True,
                            text=True, timeout=180)
    print(result.stdout, end="")
    failure = f": {result.stderr[-2000:]}" if result.returncode else ""
    check(result.returncode == 0, f"the notebook ran ({name}){failure}")
    with open(summary_path) as f:
        return result.stdout, json.load(f)


def check_notebook_runs(binary, work):
    from service import start_server, stop_server
    from sphles_client import Client
    from sphles_run import RunDirectory

    server, url, data = start_server(binary, os.path.join(work, "service"),
                                     name="check_notebook")
    try:
        plots = os.path.join(work, "plots")
        os.makedirs(plots)
        runs = os.path.join(data, "runs")
        out, summary = run_notebook(work, "with-matplotlib", {
            "SPHLES_URL": url, "SPHLES_RUNS": runs, "SPHLES_PLOTS": plots}, False)
        client = Client(url)
        run_id = summary["run_id"]
        check(client.run(run_id)["state"] == "finished", f"run {run_id} finished on the server")
        check(HINT not in out and summary["plotted"], "matplotlib found")
        check("no reference run of this flow yet" in out and summary["reference_shells"] > 10,
              "the reference computed by the service and its spectrum read")
        names = sorted(os.path.basename(p) for p in summary["saved"])
        check(names == ["workflow_omega2.png", "workflow_spectrum.png"]
              and all(os.path.dirname(p) == plots for p in summary["saved"]),
              f"figures written to SPHLES_PLOTS: {names}")
        for path in summary["saved"]:
            with open(path, "rb") as f:
                head = f.read(8)
            check(head == b"\x89PNG\r\n\x1a\n" and os.path.getsize(path) > 5000,
                  f"{os.path.basename(path)} is a PNG of {os.path.getsize(path)} bytes")
        check(summary["omega2_shape"] == [64, 64], "the ω² slice is 64 × 64 (2 × 32 points)")
        offline = RunDirectory(os.path.join(runs, run_id))
        check(summary["offline"] == offline.path and "same spectrum as the service's: True" in out
              and "same ω² slice: True" in out, "the offline reader sees the service's numbers")
        e_v_grid = offline.analysis()["e_v_grid"][-1]
        check(abs(summary["energy_sum"] - e_v_grid) < 1e-12,
              f"the notebook's Σ E Δk {summary['energy_sum']:.12f} = e_v_grid of the run")

        hidden = os.path.join(work, "plots-hidden")
        os.makedirs(hidden)
        out, summary = run_notebook(work, "without-matplotlib", {
            "SPHLES_URL": url, "SPHLES_RUNS": "", "SPHLES_PLOTS": hidden}, True)
        check(HINT in out and not summary["plotted"], f"without matplotlib: '{HINT}'")
        check(summary["saved"] == [] and os.listdir(hidden) == [], "and no figure written")
        check("no reference run of this flow yet" not in out,
              "the second run uses the reference the first computed")
        check("skipping the offline reading" in out and summary["offline"] is None,
              "without SPHLES_RUNS the offline part is skipped")
    finally:
        stop_server(server)


def check_kernel_study(binary, work):
    from service import start_server, stop_server

    server, url, _ = start_server(binary, os.path.join(work, "study"), name="check_notebook")
    try:
        result = subprocess.run(
            [sys.executable, os.path.join(EXAMPLES, "kernel_study.py"), "--url", url,
             "--particles", "16", "--end", "0.2", "--reference-points", "16"],
            capture_output=True, text=True, timeout=180)
        print(result.stdout, end="")
        check(result.returncode == 0,
              "kernel_study.py ran" + (f": {result.stderr[-2000:]}" if result.returncode else ""))
    finally:
        stop_server(server)
    rows = [line.split() for line in result.stdout.splitlines()
            if line.split() and line.split()[0] in KERNELS]
    check([row[0] for row in rows] == KERNELS, "a table row per kernel")
    values = [[float(cell) for cell in row[1:]] for row in rows]
    check(all(len(row) == len(values[0]) >= 6 and all(math.isfinite(v) for v in row)
              for row in values), "every cell a finite number")
    errors = [row[4] for row in values]
    check(all(0 < e < 0.1 for e in errors) and len(set(errors)) == 3,
          f"e_v errors against the analytic decay, one per kernel: {errors}")


def main():
    if len(sys.argv) >= 4 and sys.argv[1] == "--exec":
        execute(sys.argv[2], sys.argv[3], "--hide-matplotlib" in sys.argv[4:])
        return
    # Only here: the child that runs the notebook must find the client as the notebook does.
    sys.path.insert(0, CLIENT)
    binary, work = os.path.abspath(sys.argv[1]), os.path.abspath(sys.argv[2])
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    check_notebook_file()
    check_notebook_runs(binary, work)
    check_kernel_study(binary, work)
    print("check_notebook: all checks passed")


if __name__ == "__main__":
    main()
