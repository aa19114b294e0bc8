"""HDF5 run file (SPEC section 8) and its XDMF sidecar: names, shapes, units, robustness."""

import json
import os
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest

from taichi_sph.io.hdf5 import FORMAT, RunFile, RunFileError, RunWriter, unit_for
from taichi_sph.io.xdmf import write_xdmf

ROOT = Path(__file__).resolve().parents[1]
N = 50
F = 3


def _kind():
    kind = np.zeros(N, dtype=np.int8)
    kind[30:42] = 1  # wall
    kind[42:47] = 2  # soil
    kind[47:] = 3  # air
    return kind


def _fields(dim, step, rng):
    active = np.ones(N, dtype=bool)
    active[step] = False
    return {
        "position": rng.random((N, dim)),
        "velocity": rng.standard_normal((N, dim)),
        "pressure": rng.random(N) * 1e3,
        "density": 1000.0 + rng.random(N),
        "active": active,
        "porosity": np.full(N, 0.4),
    }


def _write_run(path, dim, rng, close=True, extra=None):
    markers = {
        "position": rng.random((7, dim)),
        "porosity": np.full(7, 0.35),
        "d50": np.full(7, 0.01),
    }
    w = RunWriter(
        path,
        mode="isph",
        dim=dim,
        dx=0.01,
        arch="cpu",
        config_yaml="mode: isph\ndim: %d\ndx: 0.01\n" % dim,
        kind=_kind(),
        ids=np.arange(N, dtype=np.int64),
        code_version="0.1.0",
        markers=markers,
        attrs={"mass": 0.1, "rho_w": 1000.0, "n_particles": N},
    )
    written = []
    for i in range(F):
        fr = _fields(dim, i, rng)
        fr.update({k: rng.random((N, *shape)) for k, shape in (extra or {}).items()})
        w.write_frame(0.1 * i, fr)
        written.append(fr)
    for s0 in (0, 4):  # diagnostics in two appends
        k = 4 if s0 == 0 else 3
        steps = np.arange(s0, s0 + k)
        w.append_diagnostics(
            {
                "time": steps * 0.01,
                "dt": np.full(k, 0.01),
                "kinetic_energy": np.linspace(0, 1, k),
                "max_speed": np.linspace(0, 2, k),
                "water_volume": np.full(k, 0.5),
                "cg_iterations": steps + 10,
                "cg_residual": np.full(k, 1e-9),
                "wall_seconds": np.full(k, 0.5),
            }
        )
    w.append_probe("p_bottom", [0.0, 0.1], [10.0, 11.0], "Pa")
    w.append_probe("p_bottom", [0.2], [12.0], "Pa")
    w.append_probe("level", [0.0, 0.1], np.ones((2, 3)), "m")
    w.set_attrs(status="finished", exit_reason="end_time", mipps=1.5)
    if close:
        w.close()
        w.close()  # idempotent
    return w, written, markers


@pytest.mark.parametrize("dim", [2, 3])
def test_roundtrip_spec_names(tmp_path, dim):
    rng = np.random.default_rng(dim)
    path = tmp_path / "sub" / "run.h5"  # parent directory is created
    _, written, markers = _write_run(path, dim, rng)

    # raw layout with h5py: every SPEC 8 name
    with h5py.File(path, "r") as f:
        a = f.attrs
        assert a["format"] == "taichi-sph" and int(a["format_version"]) == 1
        for key in ("mode", "dim", "dx", "code_version", "arch", "config_yaml"):
            assert key in a, key
        assert a["mode"] == "isph" and int(a["dim"]) == dim and float(a["dx"]) == 0.01
        assert f["particles/kind"].dtype == np.int8 and f["particles/kind"].shape == (N,)
        assert f["particles/id"].shape == (N,)
        assert f["markers/position"].shape == (7, dim)
        assert f["markers/porosity"].shape == (7,) and f["markers/d50"].shape == (7,)
        fr = f["frames"]
        assert fr["time"].shape == (F,)
        assert fr["position"].shape == (F, N, dim) and fr["velocity"].shape == (F, N, dim)
        for name in ("pressure", "density", "active", "porosity"):
            assert fr[name].shape == (F, N), name
        # /frames/active is an HDF5 boolean (docs/output.md): h5py's enum FALSE = 0 / TRUE = 1 of int8
        assert fr["active"].dtype == np.bool_ and "dtype" not in fr["active"].attrs
        tid = fr["active"].id.get_type()
        assert tid.get_class() == h5py.h5t.ENUM and tid.get_size() == 1
        assert fr["active"][()].dtype == np.bool_
        assert fr["position"].maxshape[0] is None and fr["position"].chunks == (1, N, dim)
        units = {k: fr[k].attrs["units"] for k in fr}
        assert units["time"] == "s" and units["position"] == "m" and units["velocity"] == "m/s"
        assert units["pressure"] == "Pa" and units["density"] == "kg/m^3" and units["active"] == "1"
        d = f["diagnostics"]
        for name in ("time", "dt", "kinetic_energy", "max_speed", "water_volume", "cg_iterations",
                     "cg_residual", "wall_seconds"):
            assert d[name].shape == (7,), name
            assert "units" in d[name].attrs
        assert d["kinetic_energy"].attrs["units"] == ("J/m" if dim == 2 else "J")
        assert d["water_volume"].attrs["units"] == ("m^2" if dim == 2 else "m^3")
        assert d["dt"].attrs["units"] == "s"
        assert f["probes/p_bottom/time"].shape == (3,) and f["probes/p_bottom/value"].shape == (3,)
        assert f["probes/p_bottom/value"].attrs["units"] == "Pa"
        assert f["probes/level/value"].shape == (2, 3)

    # reader
    with RunFile(path) as run:
        assert run.mode == "isph" and run.dim == dim and run.dx == 0.01
        assert run.n_frames == F
        np.testing.assert_allclose(run.times, [0.0, 0.1, 0.2])
        assert set(run.field_names) == set(written[0])
        assert run.kind.dtype == np.int8 and np.array_equal(run.kind, _kind())
        assert np.array_equal(run.ids, np.arange(N))
        assert "dx: 0.01" in run.config_yaml
        for i in range(F):
            got = run.frame(i)
            for name, arr in written[i].items():
                np.testing.assert_array_equal(got[name], arr)
            assert got["active"].dtype == np.bool_
        last = run.frame(-1)
        np.testing.assert_array_equal(last["position"], written[-1]["position"])
        np.testing.assert_array_equal(run.field("pressure", 1), written[1]["pressure"])
        with pytest.raises(IndexError):
            run.frame(F)
        with pytest.raises(KeyError):
            run.field("nope", 0)
        diag = run.diagnostics()
        np.testing.assert_array_equal(diag["cg_iterations"], [10, 11, 12, 13, 14, 15, 16])
        probes = run.probes()
        np.testing.assert_allclose(probes["p_bottom"][0], [0.0, 0.1, 0.2])
        np.testing.assert_allclose(probes["p_bottom"][1], [10.0, 11.0, 12.0])
        assert probes["level"][1].shape == (2, 3)
        mk = run.markers()
        np.testing.assert_array_equal(mk["position"], markers["position"])
        assert run.attrs["status"] == "finished" and run.attrs["mass"] == 0.1

        s = run.summary()
    text = json.dumps(s, allow_nan=False)
    s = json.loads(text)
    assert s["mode"] == "isph" and s["dim"] == dim and s["format_version"] == 1
    assert s["n_particles"] == {"total": N, "water": 30, "wall": 12, "soil": 5, "air": 3}
    assert s["n_frames"] == F and s["time_range"] == [0.0, 0.2]
    assert s["frames"]["position"]["shape"] == [F, N, dim]
    assert s["frames"]["position"]["units"] == "m"
    assert s["frames"]["active"]["dtype"] == "bool"
    assert s["diagnostics"]["n_steps"] == 7
    assert s["diagnostics"]["columns"]["cg_iterations"]["last"] == 16
    assert s["diagnostics"]["wall_seconds_total"] == pytest.approx(3.5)
    assert s["diagnostics"]["cg_iterations_mean"] == pytest.approx(13.0)
    assert s["diagnostics"]["cg_iterations_max"] == 16
    assert set(s["probes"]) == {"p_bottom", "level"}
    assert s["probes"]["p_bottom"]["samples"] == 3
    assert s["markers"] == 7
    assert s["attrs"]["status"] == "finished" and s["attrs"]["exit_reason"] == "end_time"
    assert s["attrs"]["mipps"] == 1.5 and s["attrs"]["n_particles"] == N


def test_units_table():
    assert unit_for("kinetic_energy", 2) == "J/m" and unit_for("kinetic_energy", 3) == "J"
    assert unit_for("water_volume", 2) == "m^2" and unit_for("water_volume_layer", 3) == "m^3"
    assert unit_for("something_new", 3) == "1"
    assert unit_for("something_new", 3, {"something_new": "N"}) == "N"


@pytest.mark.parametrize("dim", [2, 3])
def test_xdmf_references_exist(tmp_path, dim):
    rng = np.random.default_rng(10 + dim)
    path = tmp_path / "case.h5"
    # a stress-like field with more than dim components per particle
    stress_shape = (2, 2) if dim == 2 else (6,)
    _write_run(path, dim, rng, extra={"stress": stress_shape})
    xpath = write_xdmf(path, markers=True)
    assert xpath == tmp_path / "case.xdmf" and xpath.exists()

    root = ET.parse(xpath).getroot()
    assert root.tag == "Xdmf" and root.get("Version") == "3.0"
    series = root.find("Domain/Grid")
    assert series.get("GridType") == "Collection" and series.get("CollectionType") == "Temporal"
    grids = series.findall("Grid")
    assert len(grids) == F
    times = [float(g.find("Time").get("Value")) for g in grids]
    np.testing.assert_allclose(times, [0.0, 0.1, 0.2])
    for g in grids:
        topo = g.find("Topology")
        assert topo.get("TopologyType") == "Polyvertex" and topo.get("NumberOfElements") == str(N)
        assert g.find("Geometry").get("GeometryType") == ("XY" if dim == 2 else "XYZ")
        names = {a.get("Name"): a.get("AttributeType") for a in g.findall("Attribute")}
        assert names["velocity"] == "Vector" and names["pressure"] == "Scalar"
        assert {"density", "active", "porosity", "kind", "id"} <= set(names)
        assert names["stress"] == ("Matrix" if dim == 2 else "Tensor6")
    mgrid = root.find("Domain/Grid[@Name='markers']")
    assert mgrid is not None and mgrid.find("Topology").get("NumberOfElements") == "7"

    n_refs = 0
    with h5py.File(path, "r") as f:
        for item in root.iter("DataItem"):
            if item.get("Format") != "HDF":
                continue
            fname, _, h5p = item.text.strip().partition(":")
            assert fname == "case.h5"  # relative: the pair can move together
            assert h5p in f, h5p
            dims = tuple(int(x) for x in item.get("Dimensions").split())
            assert f[h5p].shape == dims, (h5p, dims)
            n_refs += 1
        # each HyperSlab selects one existing frame and its result size matches the count
        for slab in root.iter("DataItem"):
            if slab.get("ItemType") != "HyperSlab":
                continue
            sel, src = slab.findall("DataItem")
            rank = len(src.get("Dimensions").split())
            vals = [int(x) for x in sel.text.split()]
            start, count = vals[:rank], vals[2 * rank:]
            assert 0 <= start[0] < F and count[0] == 1
            result = [int(x) for x in slab.get("Dimensions").split()]
            assert int(np.prod(result)) == int(np.prod(count))
    assert n_refs > F * 7


def test_write_frame_field_mismatch(tmp_path):
    rng = np.random.default_rng(0)
    with RunWriter(tmp_path / "r.h5", mode="wcsph_biot", dim=2, dx=0.01, arch="cpu", config_yaml="",
                   kind=_kind(), ids=np.arange(N), code_version="x") as w:
        w.write_frame(0.0, _fields(2, 0, rng))
        fr = _fields(2, 1, rng)
        del fr["density"]
        with pytest.raises(ValueError, match="density"):
            w.write_frame(0.1, fr)
        fr = _fields(2, 1, rng)
        fr["stress"] = np.zeros((N, 3))
        with pytest.raises(ValueError, match="stress"):
            w.write_frame(0.1, fr)
        fr = _fields(2, 1, rng)
        fr["pressure"] = np.zeros(N + 1)
        with pytest.raises(ValueError, match="pressure"):
            w.write_frame(0.1, fr)
        with pytest.raises(ValueError, match="dt"):
            w.append_diagnostics({"time": np.zeros(3), "dt": np.zeros(2)})
        assert w.n_frames == 1
    with RunFile(tmp_path / "r.h5") as run:
        assert run.n_frames == 1  # failed calls left no partial frame


def test_runfile_errors(tmp_path):
    missing = tmp_path / "missing.h5"
    with pytest.raises(RunFileError, match="missing.h5"):
        RunFile(missing)
    text = tmp_path / "notes.h5"
    text.write_text("this is not HDF5\n")
    with pytest.raises(RunFileError, match="notes.h5"):
        RunFile(text)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(RunFileError, match="other.h5") as exc:
        RunFile(other)
    assert "\n" not in str(exc.value)
    assert issubclass(RunFileError, ValueError)


def test_killed_writer_leaves_frames_readable(tmp_path):
    path = tmp_path / "killed.h5"
    script = textwrap.dedent(
        f"""
        import os, numpy as np
        from taichi_sph.io.hdf5 import RunWriter
        n = 20
        w = RunWriter({str(path)!r}, mode="isph", dim=3, dx=0.02, arch="cpu", config_yaml="dim: 3",
                      kind=np.zeros(n, np.int8), ids=np.arange(n), code_version="t")
        for i in range(2):
            w.write_frame(0.5 * i, {{"position": np.full((n, 3), float(i)), "active": np.ones(n, bool)}})
        w.append_diagnostics({{"time": [0.0, 0.5], "dt": [0.5, 0.5]}})
        os._exit(0)  # no close, no atexit handlers
        """
    )
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    res = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 0, res.stderr
    with RunFile(path) as run:
        assert run.n_frames == 2
        np.testing.assert_array_equal(run.frame(-1)["position"], np.ones((20, 3)))
        assert run.frame(1)["active"].all()
        assert run.diagnostics()["dt"].shape == (2,)
    assert write_xdmf(path).exists()


def test_booleans_read_as_0_1_by_an_xdmf_reader(tmp_path):
    """VTK's XDMF reader (what ParaView opens the sidecar with) asks HDF5 for unsigned chars and gets
    the booleans of /frames/active as 0 / 1, frame by frame."""
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    rng = np.random.default_rng(4)
    path = tmp_path / "b.h5"
    _, written, _ = _write_run(path, 2, rng)
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(write_xdmf(path)))
    reader.UpdateInformation()
    for i, t in enumerate([0.0, 0.1, 0.2]):
        reader.GetOutputInformation(0).Set(vtk.vtkStreamingDemandDrivenPipeline.UPDATE_TIME_STEP(), t)
        reader.Update()
        out = reader.GetOutputDataObject(0)
        grid = out.GetBlock(0) if out.IsA("vtkMultiBlockDataSet") else out
        got = vtk_to_numpy(grid.GetPointData().GetArray("active"))
        np.testing.assert_array_equal(got, written[i]["active"].astype(np.uint8))


def test_booleans_of_earlier_files_read_and_resume(tmp_path):
    """Files of earlier versions hold booleans as uint8 with attribute dtype = "bool": they read as bool,
    and a resumed run appends to them in their own dtype."""
    path = tmp_path / "old.h5"
    n = 4
    with RunWriter(path, mode="isph", dim=2, dx=0.01, arch="cpu", config_yaml="dim: 2", kind=np.zeros(n, np.int8),
                   ids=np.arange(n), code_version="t") as w:
        w.write_frame(0.0, {"position": np.zeros((n, 2)), "active": np.ones(n, bool)})
    with h5py.File(path, "r+") as f:  # rewrite /frames/active the old way
        del f["frames/active"]
        ds = f["frames"].create_dataset("active", data=np.ones((1, n), np.uint8), maxshape=(None, n), chunks=(1, n))
        ds.attrs["dtype"] = "bool"
        ds.attrs["units"] = "1"
    w = RunWriter.reopen(path, n_frames=1, n_diagnostics=0, probe_samples={})
    w.write_frame(0.1, {"position": np.zeros((n, 2)), "active": np.array([True, False, True, False])})
    w.close()
    with RunFile(path) as run:
        assert run.frame(1)["active"].dtype == np.bool_
        np.testing.assert_array_equal(run.field("active", 1), [True, False, True, False])
        assert run.summary()["frames"]["active"]["dtype"] == "bool"
    with h5py.File(path, "r") as f:
        assert f["frames/active"].dtype == np.uint8


def test_writer_closed_and_reader_on_live_file(tmp_path):
    rng = np.random.default_rng(1)
    w, _, _ = _write_run(tmp_path / "live.h5", 3, rng, close=False)
    with RunFile(tmp_path / "live.h5") as run:  # readable while the writer holds it open
        assert run.n_frames == F
    w.close()
    with pytest.raises(ValueError):
        w.write_frame(1.0, {})
    with RunFile(tmp_path / "live.h5") as run:
        assert run.attrs["format"] == FORMAT
