# SPDX-License-Identifier: GPL-3.0-or-later
"""Opens every output kind of the runs made by make_runs.py in ParaView (pvbatch), with the
reader ParaView picks itself, and checks what it reads:

- snapshots/particles.xdmf (Xdmf3 reader): one vertex cell per particle, the snapshot times,
  the id, velocity and field arrays, values equal to those h5py reads;
- checkpoints/ckpt_*.xdmf2 (XDMF 2 reader): the same for a checkpoint (vectors joined from
  components; 2D: z = 0);
- slices/{field}.pvd and the .vti files: the slice times, the plane's shape and origin, values
  equal to the .npy next to them;
- fields/fields.pvd (3D): the whole grid with a 3-component velocity, whose x-normal plane is
  the slice of the same time.
With --screenshots DIR it also renders one picture of each kind.

usage: pvbatch check_paraview.py RUNS_DIR [--screenshots DIR]
(pictures need an X server: xvfb-run -a pvbatch ...; reading does not)
"""
import math
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from common import check, failures, finish, index_rows  # noqa: E402

import h5py
import numpy as np
from paraview import servermanager
from paraview import simple
from vtkmodules.util.numpy_support import vtk_to_numpy


def fetch(source, time):
    source.UpdatePipeline(time)
    data = servermanager.Fetch(source)
    if data.IsA("vtkMultiBlockDataSet") or data.IsA("vtkPartitionedDataSetCollection"):
        it = data.NewIterator()
        it.InitTraversal()
        data = it.GetCurrentDataObject()
    return data


def point_array(data, name):
    array = data.GetPointData().GetArray(name)
    return None if array is None else vtk_to_numpy(array)


def check_particles(xdmf, h5_of_time, fields, dimension, reader_name):
    reader = simple.OpenDataFile(str(xdmf.resolve()))
    check(reader is not None, f"{xdmf}: ParaView found no reader")
    if reader is None:
        return None
    check(reader.GetXMLName().startswith(reader_name),
          f"{xdmf}: ParaView chose {reader.GetXMLName()}, not {reader_name}")
    times = list(reader.TimestepValues) if reader.TimestepValues else [0.0]
    check(len(times) == len(h5_of_time) or len(h5_of_time) == 1,
          f"{xdmf}: ParaView sees times {times}")
    for t, h5 in h5_of_time.items():
        data = fetch(reader, t)
        with h5py.File(h5, "r") as f:
            n = int(f.attrs["num_particles"])
            check(data.GetNumberOfPoints() == n, f"{xdmf} t={t}: {data.GetNumberOfPoints()} points")
            check(data.GetNumberOfCells() == n,
                  f"{xdmf} t={t}: {data.GetNumberOfCells()} cells for {n} particles")
            if data.GetNumberOfCells() == n:
                # VTK_VERTEX or VTK_POLY_VERTEX, one point each
                check(data.GetCellType(0) in (1, 2) and data.GetCell(0).GetNumberOfPoints() == 1,
                      f"{xdmf}: cell type {data.GetCellType(0)}")
            points = vtk_to_numpy(data.GetPoints().GetData())
            reference = f["position"][...] if "position" in f else np.stack(
                [f[f"particles/position_{a}"][...] for a in "xyz"[:dimension]] +
                ([np.zeros(n)] if dimension == 2 else []), axis=1)
            check(np.array_equal(points, reference), f"{xdmf} t={t}: positions differ")
            for name in ["id", "velocity"] + fields:
                values = point_array(data, name)
                check(values is not None, f"{xdmf} t={t}: no point array '{name}'")
                if values is None:
                    continue
                if name == "id":
                    ids = f["id"][...] if "id" in f else f["particles/id"][...]
                    check(np.array_equal(values.astype(np.uint64), ids), f"{xdmf}: ids differ")
                elif name == "velocity":
                    check(values.shape == (n, 3), f"{xdmf}: velocity has shape {values.shape}")
                    if "velocity" in f:
                        check(np.array_equal(values, f["velocity"][...]), f"{xdmf}: velocity")
                    else:
                        for d, a in enumerate("xyz"[:dimension]):
                            check(np.array_equal(values[:, d], f[f"particles/velocity_{a}"][...]),
                                  f"{xdmf}: velocity_{a}")
                        if dimension == 2:
                            check(np.all(values[:, 2] == 0.0), f"{xdmf}: 2D velocity z is not 0")
                else:
                    key = name if name in f else f"particles/{name}"
                    check(np.array_equal(values, f[key][...]), f"{xdmf}: {name} differs")
    return reader


def check_slices(run, field):
    pvd = run / "slices" / f"{field}.pvd"
    rows = [r for r in index_rows(run / "slices" / "index.csv") if r["field"] == field]
    reader = simple.OpenDataFile(str(pvd.resolve()))
    check(reader is not None, f"{pvd}: ParaView found no reader")
    if reader is None:
        return None
    times = list(reader.TimestepValues)
    check(len(times) == len(rows) and all(math.isclose(a, float(r["t"]), abs_tol=1e-12)
                                          for a, r in zip(times, rows)),
          f"{pvd}: times {times}")
    for r in rows:
        t = float(r["t"])
        data = fetch(reader, t)
        check(data.IsA("vtkImageData"), f"{pvd}: {data.GetClassName()} is no image")
        expected = np.load(run / "slices" / r["file"])
        dims = [1, 1, 1]
        axes = "xyz"
        dims[axes.index(r["axis_u"])] = int(r["width"])
        dims[axes.index(r["axis_v"])] = int(r["height"])
        check(list(data.GetDimensions()) == dims, f"{pvd} t={t}: dimensions {data.GetDimensions()}")
        origin = [0.0, 0.0, 0.0]
        origin[axes.index(r["normal_axis"])] = float(r["position"])
        check(np.allclose(data.GetOrigin(), origin, atol=0, rtol=0),
              f"{pvd} t={t}: origin {data.GetOrigin()} for {origin}")
        values = point_array(data, field)
        check(values is not None and np.array_equal(values, expected.ravel()),
              f"{pvd} t={t}: values differ from {r['file']}")
        units = data.GetFieldData().GetAbstractArray("units")
        check(units is not None and units.GetValue(0) == f"{field} [{r['units']}]",
              f"{pvd}: units field data")
    return reader


def check_fields(run):
    """fields/fields.pvd: the whole grid per snapshot; its x-normal plane is the slice."""
    pvd = run / "fields" / "fields.pvd"
    rows = index_rows(run / "fields" / "index.csv")
    slices = {(r["field"], float(r["t"])): r for r in index_rows(run / "slices" / "index.csv")}
    reader = simple.OpenDataFile(str(pvd.resolve()))
    check(reader is not None, f"{pvd}: ParaView found no reader")
    if reader is None:
        return None
    check(len(reader.TimestepValues) == len(rows), f"{pvd}: times {list(reader.TimestepValues)}")
    for r in rows:
        t = float(r["t"])
        data = fetch(reader, t)
        m = int(r["points_per_side"])
        check(list(data.GetDimensions()) == [m, m, m], f"{pvd} t={t}: {data.GetDimensions()}")
        velocity = point_array(data, "velocity")
        check(velocity is not None and velocity.shape == (m ** 3, 3), f"{pvd}: velocity")
        for field in ("omega2", "tau_sfs"):
            values = point_array(data, field)
            s = slices.get((field, t))
            check(values is not None and s is not None, f"{pvd} t={t}: {field}")
            if values is None or s is None:
                continue
            i = round(float(s["position"]) / float(s["spacing"]))
            plane = values.reshape(m, m, m)[:, :, i]  # (k, j) at x index i
            check(np.array_equal(plane, np.load(run / "slices" / s["file"])),
                  f"{pvd} t={t}: the {field} plane differs from {s['file']}")
    return reader


def screenshot(source, array, path, time, representation, view_direction):
    view = simple.CreateView("RenderView")
    view.ViewSize = [640, 480]
    view.OrientationAxesVisibility = 1
    view.ViewTime = time
    display = simple.Show(source, view)
    display.SetRepresentationType(representation)
    display.PointSize = 4
    simple.ColorBy(display, ("POINTS", array))
    display.RescaleTransferFunctionToDataRange(True, False)
    display.SetScalarBarVisibility(view, True)
    view.CameraPosition = view_direction
    view.CameraFocalPoint = [0, 0, 0]
    view.ResetCamera()
    simple.SaveScreenshot(str(path), view, ImageResolution=[640, 480])
    simple.Delete(view)


def main():
    runs = pathlib.Path(sys.argv[1])
    shots = pathlib.Path(sys.argv[sys.argv.index("--screenshots") + 1]) \
        if "--screenshots" in sys.argv else None
    for key, dimension, fields in (("3d", 3, ["omega2", "tau_sfs"]), ("2d", 2, ["omega2"])):
        run = runs / key
        snapshots = {float(r["t"]): run / "snapshots" / r["file"]
                     for r in index_rows(run / "snapshots" / "index.csv")}
        particles = check_particles(run / "snapshots" / "particles.xdmf", snapshots, fields,
                                    dimension, "Xdmf3Reader")
        checkpoint = sorted((run / "checkpoints").glob("ckpt_*.h5"))[-1]
        with h5py.File(checkpoint, "r") as f:
            t = float(f.attrs["time"])
        ckpt = check_particles(checkpoint.with_suffix(".xdmf2"), {t: checkpoint},
                               ["mass", "density", "pressure"], dimension, "XdmfReader")
        slices = [check_slices(run, f) for f in fields]
        grid = check_fields(run) if dimension == 3 else None
        if shots and failures == []:
            shots.mkdir(parents=True, exist_ok=True)
            last = max(snapshots)
            side = [10, 0, 0] if dimension == 3 else [0, 0, 10]
            screenshot(particles, "omega2", shots / f"paraview_{key}_snapshot.png", last,
                       "Points", [10, 6, 8] if dimension == 3 else side)
            screenshot(ckpt, "pressure", shots / f"paraview_{key}_checkpoint.png", t, "Points",
                       [10, 6, 8] if dimension == 3 else side)
            screenshot(slices[0], fields[0], shots / f"paraview_{key}_slice.png", last, "Surface",
                       side)
            if grid is not None:
                screenshot(grid, "omega2", shots / f"paraview_{key}_fields.png", last, "Surface",
                           [10, 6, 8])
    finish()


if __name__ == "__main__":
    main()
