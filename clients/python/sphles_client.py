# SPDX-License-Identifier: GPL-3.0-or-later
"""A small Python client of the sphles service (docs/api.md).

Standard library only, plus NumPy for arrays and Debian's python3-websocket (``websocket``)
for live streams; both are imported when first needed.

    from sphles_client import Client
    c = Client("http://127.0.0.1:8080")
    run = c.create(preset="tgv2d", patch={"particles_per_side": 32, "time": {"end": 1.0}})
    for sample in c.stream_metrics(run["id"], until_state="finished"):
        print(sample["time"], sample["kinetic_energy"])
    series = c.timeseries(run["id"])          # {"time": array, "kinetic_energy": array, ...}
    k, E = c.spectrum(run["id"])              # the latest spectrum as arrays
    omega2 = c.slice(run["id"], "omega2")     # the latest ω² slice as a 2D array
"""

import json
import os
import struct
import time
import urllib.error
import urllib.parse
import urllib.request

__all__ = ["Client", "ApiError"]


class ApiError(Exception):
    """An error answer of the server: ``status`` (HTTP), ``message`` and ``field`` (the request
    field it names, or None)."""

    def __init__(self, status, message, field=None):
        super().__init__(f"{status}: {message}" + (f" (field {field})" if field else ""))
        self.status = status
        self.message = message
        self.field = field


class Client:
    """The REST API and the WebSocket stream of one sphles server. ``token`` is sent as
    ``Authorization: Bearer`` (needed for mutating calls when the server has one)."""

    def __init__(self, base_url, token=None, timeout=60.0):
        self.base_url = base_url.rstrip("/")
        self.token = token
        self.timeout = timeout

    # -- plumbing -------------------------------------------------------------------------------

    def _request(self, method, path, body=None, raw=False):
        headers = {"Accept": "application/json"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        data = None
        if body is not None:
            data = json.dumps(body).encode()
            headers["Content-Type"] = "application/json"
        request = urllib.request.Request(self.base_url + path, data=data, headers=headers,
                                         method=method)
        try:
            with urllib.request.urlopen(request, timeout=self.timeout) as response:
                content = response.read()
        except urllib.error.HTTPError as e:
            content = e.read()
            try:
                error = json.loads(content)["error"]
            except (ValueError, KeyError, TypeError):
                raise ApiError(e.code, content.decode(errors="replace") or e.reason) from None
            raise ApiError(error.get("status", e.code), error.get("message", ""),
                           error.get("field")) from None
        except urllib.error.URLError as e:
            raise ApiError(0, f"server unreachable: {e.reason}") from None
        if raw:
            return content
        return json.loads(content) if content else None

    @staticmethod
    def _run(run_id):
        return "/api/runs/" + urllib.parse.quote(run_id, safe="")

    @staticmethod
    def _columns(answer):
        import numpy as np
        return {name: np.array(values, dtype=float)
                for name, values in zip(answer["columns"], answer["data"])}

    # -- runs -----------------------------------------------------------------------------------

    def health(self):
        return self._request("GET", "/api/health")

    def presets(self):
        return self._request("GET", "/api/presets")

    def scenes(self):
        """The server's scene files (scenes/): {"scenes": [{..., "file", "scene"}], "skipped":
        [{"file", "error"}]}; create a run of one with create(scene=entry["scene"])."""
        return self._request("GET", "/api/scenes")

    def runs(self):
        return self._request("GET", "/api/runs")

    def run(self, run_id):
        """The run's detail: summary, scene, latest metrics, what is available."""
        return self._request("GET", self._run(run_id))

    def create(self, preset=None, scene=None, patch=None, overrides=None, name=None, start=True,
               ranks=1):
        """Creates a run from a preset or a scene document (exactly one), a JSON merge patch and
        dotted ``key=value`` overrides; starts it unless ``start`` is False. The run summary."""
        body = {"start": start}
        if preset is not None:
            body["preset"] = preset
        if scene is not None:
            body["scene"] = scene
        if patch:
            body["patch"] = patch
        if overrides:
            body["overrides"] = list(overrides)
        if name:
            body["name"] = name
        if ranks != 1:
            body["ranks"] = ranks
        return self._request("POST", "/api/runs", body)

    def estimate(self, **create_arguments):
        """What ``create`` with the same arguments would need and take (nothing is created)."""
        body = {k: v for k, v in create_arguments.items() if v is not None}
        return self._request("POST", "/api/estimate", body)

    def start(self, run_id):
        return self._request("POST", self._run(run_id) + "/start")

    def pause(self, run_id):
        return self._request("POST", self._run(run_id) + "/pause")

    def resume(self, run_id):
        return self._request("POST", self._run(run_id) + "/resume")

    def stop(self, run_id):
        return self._request("POST", self._run(run_id) + "/stop")

    def delete(self, run_id):
        return self._request("DELETE", self._run(run_id))

    def change(self, run_id, patch):
        """A live change (JSON merge patch of the scene); the names of the changed fields."""
        return self._request("PATCH", self._run(run_id) + "/parameters", patch)["changed"]

    def wait(self, run_id, states=("finished", "stopped", "failed"), timeout=600.0, poll=0.2):
        """Polls until the run is in one of ``states``; its summary. TimeoutError otherwise."""
        deadline = time.monotonic() + timeout
        while True:
            summary = self.run(run_id)
            if summary["state"] in states:
                return summary
            if time.monotonic() > deadline:
                raise TimeoutError(f"run {run_id} is {summary['state']} after {timeout} s")
            time.sleep(poll)

    # -- products as arrays ---------------------------------------------------------------------

    def timeseries(self, run_id, max_points=None):
        """timeseries.csv as NumPy arrays by column (time, step, dt, kinetic_energy, ...), every
        page fetched (or decimated to ``max_points`` by the server)."""
        import numpy as np
        path = self._run(run_id) + "/timeseries"
        if max_points:
            return self._columns(self._request("GET", f"{path}?max_points={max_points}"))
        columns, since = None, None
        while True:
            answer = self._request("GET", path + ("" if since is None else f"?since_step={since}"))
            page = self._columns(answer)
            columns = page if columns is None else {
                name: np.concatenate([columns[name], page[name]]) for name in columns}
            if not answer.get("more"):
                return columns
            since = answer["next_since_step"]

    def analysis(self, run_id):
        """Every analysis frame's scalars (stats/snapshots.csv) as arrays by column."""
        return self._columns(self._request("GET", self._run(run_id) + "/analysis"))

    def spectrum(self, run_id):
        """The latest energy spectrum: (k, E) as arrays [1/m], [m³/s²]."""
        import numpy as np
        s = self._request("GET", self._run(run_id) + "/spectrum")
        return np.array(s["k"], dtype=float), np.array(s["energy"], dtype=float)

    def reference(self, run_id):
        """The run's reference curve: {"label", "source", "time", "kinetic_energy",
        "dissipation"} with arrays; ApiError 404 (saying why) for runs without one."""
        answer = self._request("GET", self._run(run_id) + "/reference")
        return {"label": answer["label"], "source": answer["source"], **self._columns(answer)}

    def resolved(self, run_id, filter="none"):
        """The run's resolved scales against the reference run of its flow (SPEC §9): the
        answer of GET /api/runs/{id}/resolved as a dict ("samples" with E_res, shell ratios
        and the energy above k_kern per time, "resolved_energy_l2_misfit",
        "mean_shell_ratio", "reference", "reference_spectrum"); ``filter="kernel"`` judges
        against the reference filtered by the run's kernel (E_ref(k) Ŵ(k)²). ApiError 404
        (saying why) when there is none, 400 naming ``filter`` for another value."""
        query = "" if filter == "none" else "?filter=" + urllib.parse.quote(str(filter))
        return self._request("GET", self._run(run_id) + "/resolved" + query)

    # -- spectral references computed by the server -------------------------------------------

    @staticmethod
    def _reference_job(job_id):
        return "/api/references/" + urllib.parse.quote(job_id, safe="")

    @staticmethod
    def _reference_request(run_id, points_per_side, cfl, dry_run):
        body = {"run": run_id}
        if points_per_side is not None:
            body["points_per_side"] = points_per_side
        if cfl is not None:
            body["cfl"] = cfl
        if dry_run:
            body["dry_run"] = True
        return body

    def estimate_reference(self, run_id, points_per_side=None, cfl=None):
        """What the spectral reference of the run's flow would need, creating nothing:
        {"memory_bytes", "steps", "checkpoint_bytes", "max_wavenumber", "admitted", ...};
        ``points_per_side`` and ``cfl`` default to the run's scene's reference section."""
        return self._request("POST", "/api/references",
                             self._reference_request(run_id, points_per_side, cfl, True))

    def compute_reference(self, run_id, points_per_side=None, cfl=None):
        """Starts computing the spectral reference of the run's flow on the server (queued
        behind other reference jobs); the job: {"id", "state", "progress", "directory", ...}.
        Once it is done, ``resolved(run_id)`` judges the run against it."""
        return self._request("POST", "/api/references",
                             self._reference_request(run_id, points_per_side, cfl, False))

    def reference_jobs(self):
        """Every reference job of the server, oldest first."""
        return self._request("GET", "/api/references")

    def reference_job(self, job_id):
        """A reference job: state (queued, running, done, stopped, failed), time, step,
        progress, estimate, directory, error."""
        return self._request("GET", self._reference_job(job_id))

    def stop_reference(self, job_id):
        """Stops a queued or running job (with a checkpoint); the job."""
        return self._request("POST", self._reference_job(job_id) + "/stop")

    def resume_reference(self, job_id):
        """Queues a stopped or failed job again, to continue from its checkpoint; the job."""
        return self._request("POST", self._reference_job(job_id) + "/resume")

    def delete_reference(self, job_id):
        """Deletes a job that is done, stopped or failed, with its directory."""
        return self._request("DELETE", self._reference_job(job_id))

    def wait_reference(self, job_id, states=("done", "stopped", "failed"), timeout=600.0,
                       poll=0.2):
        """Polls until the job is in one of ``states``; the job. TimeoutError otherwise."""
        deadline = time.monotonic() + timeout
        while True:
            job = self.reference_job(job_id)
            if job["state"] in states:
                return job
            if time.monotonic() > deadline:
                raise TimeoutError(f"reference job {job_id} is {job['state']} after {timeout} s")
            time.sleep(poll)

    def log(self, run_id, lines=200):
        """The last lines of the run's run.log."""
        return self._request("GET", f"{self._run(run_id)}/log?lines={lines}", raw=True).decode()

    # -- files ----------------------------------------------------------------------------------

    def files(self, run_id):
        """Every file of the run directory: [{"path", "bytes", "modified", "url"}]."""
        return self._request("GET", self._run(run_id) + "/files")

    def download(self, run_id, path, destination=None):
        """The bytes of a run file (``path`` as ``files`` lists it); written to ``destination``
        too when given."""
        content = self._request("GET", self._run(run_id) + "/files/" + path, raw=True)
        if destination is not None:
            with open(destination, "wb") as out:
                out.write(content)
        return content

    def movie(self, run_id, field="omega2", fps=None, quality=None, destination=None):
        """The run's saved frames of ``field`` (omega2, tau_sfs, nu_t, combined, view3d) encoded
        by the server as movies/FIELD.webm; its description ({"path", "url", "frames", "width",
        "height", "duration_seconds", "bytes"}), and the video written to ``destination``."""
        body = {"field": field}
        if fps is not None:
            body["fps"] = fps
        if quality is not None:
            body["quality"] = quality
        made = self._request("POST", self._run(run_id) + "/movies", body)
        if destination is not None:
            self.download(run_id, made["path"], destination)
        return made

    def slice(self, run_id, field, time=None):
        """A saved slice of ``field`` (omega2, tau_sfs, ...) as a 2D NumPy array: the latest, or
        the one nearest to ``time``. Needs "slices" among the scene's analysis products."""
        import csv
        import io
        import numpy as np
        index = list(csv.DictReader(io.StringIO(
            self.download(run_id, "slices/index.csv").decode())))
        rows = [r for r in index if r["field"] == field]
        if not rows:
            raise ApiError(404, f"run {run_id} has no saved slice of {field}", "field")
        row = rows[-1] if time is None else min(rows, key=lambda r: abs(float(r["t"]) - time))
        return np.load(io.BytesIO(self.download(run_id, "slices/" + row["file"])))

    # -- live stream ----------------------------------------------------------------------------

    def stream(self, run_id, images=False, timeout=60.0):
        """The run's WebSocket messages as dicts (images as {"type": "image", ..., "png":
        bytes} when ``images``), until the server closes the stream."""
        import websocket  # Debian python3-websocket
        url = self.base_url.replace("http", "ws", 1) + self._run(run_id) + "/stream"
        if self.token:
            url += "?token=" + urllib.parse.quote(self.token)
        ws = websocket.create_connection(url, timeout=timeout)
        try:
            if not images:
                ws.send(json.dumps({"type": "images", "enabled": False}))
            while True:
                opcode, data = ws.recv_data()
                if opcode == websocket.ABNF.OPCODE_CLOSE:
                    return
                if opcode == websocket.ABNF.OPCODE_TEXT:
                    yield json.loads(data)
                elif opcode == websocket.ABNF.OPCODE_BINARY and images:
                    (length,) = struct.unpack(">I", data[:4])
                    header = json.loads(data[4:4 + length])
                    header["png"] = bytes(data[4 + length:])
                    yield header
        finally:
            ws.close()

    def stream_metrics(self, run_id, until_state=("finished", "stopped", "failed"),
                       timeout=60.0):
        """Metrics samples as they arrive, until the run reaches one of ``until_state``."""
        if isinstance(until_state, str):
            until_state = (until_state,)
        last_step = -1
        for message in self.stream(run_id, timeout=timeout):
            kind = message.get("type")
            if kind == "metrics":
                for sample in message["samples"]:
                    if sample["step"] > last_step:
                        last_step = sample["step"]
                        yield sample
            elif (kind == "hello" and message["run"]["state"] in until_state) or \
                    (kind == "state" and message["state"] in until_state):
                break
        # A state change is sent before metrics waiting beside it: the last samples come from
        # the time series, so that none is missed.
        answer = self._request("GET", f"{self._run(run_id)}/timeseries?since_step={last_step}"
                               if last_step >= 0 else self._run(run_id) + "/timeseries")
        rows = zip(*answer["data"])
        for row in rows:
            sample = dict(zip(answer["columns"], row))
            sample["step"] = int(sample["step"])
            if sample["step"] > last_step:
                last_step = sample["step"]
                yield sample


if __name__ == "__main__":
    print(__doc__)
    print("SPHLES_URL =", os.environ.get("SPHLES_URL", "(unset)"))
