"""What a run leaves to look at: probes that read the physics, the XDMF sidecar, pictures during the
run, `plot`, `info`, and `render` (PNG sizes, non-blank, moving frames differ, movie frame counts).

One small 2D hydrostatic run (15 particles deep, 0.3 s) is shared by the tests of this module;
rendering tests also use tiny run files written directly (a sheared block that moves)."""

import importlib.util
import json
import subprocess
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from taichi_sph.io.hdf5 import RunFile, RunWriter

from .conftest import ROOT, cli, cli_env

RHO, G = 1000.0, 9.81
H, Y_PROBE = 0.30, 0.10

HYDRO_YAML = """\
mode: isph
dim: 2
dx: 0.02
end_time: 0.3
dt: 0.002
output:
  every: 0.05
  images: {every: 0.1, field: pressure, size: [200, 150]}
tank:
  size: [0.4, 0.4]
water:
  - {min: [0.0, 0.0], max: [0.4, 0.3]}
probes:
  - {name: p_mid, type: pressure, point: [0.2, 0.1]}
  - {name: level, type: water_level, point: [0.2, 0.0], every: 0.1}
  - {name: volume, type: water_volume, box: {min: [0.0, 0.0], max: [0.4, 0.4]}, every: 0.01}
  - {name: flow, type: velocity, box: {min: [0.1, 0.0], max: [0.3, 0.2]}}
"""


def _can_render():
    if importlib.util.find_spec("pyvista") is None:
        return "pyvista is not installed (pip install 'taichi-sph[render]')"
    from taichi_sph.render.offscreen import check_offscreen

    return check_offscreen()


@pytest.fixture(scope="module")
def offscreen():
    why = _can_render()
    if why:
        pytest.skip(why)


@pytest.fixture(scope="module")
def hydro(tmp_path_factory):
    d = tmp_path_factory.mktemp("hydro")
    (d / "case.yaml").write_text(HYDRO_YAML)
    out = d / "run.h5"
    proc = cli("--config", d / "case.yaml", "--out", out, "--no-progress", timeout=600)
    assert proc.returncode == 0, proc.stderr
    return out


def test_pressure_probe_reads_rho_g_depth_and_csv_equals_run_file(hydro):
    with RunFile(hydro) as rf:
        probes = rf.probes()
        units = rf.probe_units()
        t_end = rf.times[-1]
    t, p = probes["p_mid"]
    assert t[-1] == pytest.approx(t_end) and units["p_mid"] == "Pa"
    # 2 %: at 15 particles over the depth the column settles about 0.2 dx above the initial lattice
    # (volume +0.5 %), which moves the reading against the nominal depth by up to 1.6 % (measured over 0.5 s)
    assert abs(p[-1] / (RHO * G * (H - Y_PROBE)) - 1) < 0.02
    # against the depth below the surface the level probe sees, the hydrostatic law holds within 0.7 %
    # (measured 0.3 %): 1 %
    level = probes["level"][1][-1]
    assert abs(p[-1] / (RHO * G * (level - Y_PROBE)) - 1) < 0.01
    assert abs(level - H) < 0.5 * 0.02  # the surface stays within half a particle of its start
    # water in a box around the whole tank: the particles' water volume, exactly L * H at every sample
    np.testing.assert_allclose(probes["volume"][1], 0.4 * 0.3, rtol=1e-12)
    assert len(probes["volume"][0]) == 31 and units["volume"] == "m^2"
    assert probes["flow"][1].shape == (len(probes["flow"][0]), 2)

    table = np.genfromtxt(hydro.with_suffix(".probes.csv"), delimiter=",", names=True)
    for name, cols in (("p_mid", ["p_mid"]), ("level", ["level"]), ("volume", ["volume"]),
                       ("flow", ["flow_x", "flow_y"])):
        tp, vp = probes[name]
        rows = ~np.isnan(table[cols[0]])
        np.testing.assert_array_equal(table["time"][rows], tp)
        np.testing.assert_array_equal(np.stack([table[c][rows] for c in cols], 1), vp.reshape(len(tp), -1))


def test_xdmf_beside_the_run_names_existing_datasets_with_their_shapes(hydro):
    xdmf = hydro.with_suffix(".xdmf")
    root = ET.parse(xdmf).getroot()
    grids = root.findall("Domain/Grid/Grid")
    with h5py.File(hydro, "r") as f:
        times = f["frames/time"][()]
        assert len(grids) == len(times) == 7
        np.testing.assert_allclose([float(g.find("Time").get("Value")) for g in grids], times)
        names = {a.get("Name") for a in grids[-1].findall("Attribute")}
        assert {"velocity", "pressure", "density", "active", "kind", "id"} <= names
        n_refs = 0
        for item in root.iter("DataItem"):
            if item.get("Format") != "HDF":
                continue
            fname, _, path = item.text.strip().partition(":")
            assert fname == hydro.name
            assert path in f, path
            assert f[path].shape == tuple(int(x) for x in item.get("Dimensions").split()), path
            n_refs += 1
        # per frame: geometry, 7 frame fields (velocity, pressure, density, active, free_surface,
        # isolated, flag), kind and id
        assert n_refs == 7 * (1 + 7 + 2)


def test_pictures_during_the_run(hydro, offscreen):
    from PIL import Image

    folder = hydro.with_name(hydro.stem + "_images")
    pngs = sorted(p.name for p in folder.glob("*.png"))
    # frames every 0.05 s, pictures every 0.1 s: frames 0, 2, 4, 6; size [200, 150] rounded up to 208 x 160
    assert pngs == [f"pressure_{i:05d}.png" for i in (0, 2, 4, 6)]
    assert Image.open(folder / pngs[-1]).size == (208, 160)
    assert not (folder / ".snapshots").exists()


def test_plot_and_info(hydro, tmp_path):
    from PIL import Image

    proc = cli("plot", hydro, "--out", tmp_path / "plots")
    assert proc.returncode == 0, proc.stderr
    for name in ("run_diagnostics.png", "run_probes.png"):
        img = np.asarray(Image.open(tmp_path / "plots" / name).convert("L"), dtype=float)
        assert img.std() > 10, name  # axes and curves on white; a blank figure has std 0

    proc = cli("info", hydro, "--json")
    assert proc.returncode == 0, proc.stderr
    info = json.loads(proc.stdout)
    assert info["config"]["probes"] == 4 and info["config"]["end_time"] == pytest.approx(0.3)
    assert info["probes"]["p_mid"]["type"] == "pressure" and info["probes"]["p_mid"]["point"] == [0.2, 0.1]
    assert info["probes"]["volume"]["samples"] == 31
    assert info["timings"]["status"] == "completed" and info["timings"]["steps"] == 150
    assert info["timings"]["mipps"] > 0 and "ppe_solve" in info["timings"]["phase_seconds"]
    proc = cli("info", hydro)
    assert proc.returncode == 0 and "p_mid:" in proc.stdout and "timings:" in proc.stdout


# ---- render -------------------------------------------------------------------------------------

DX = 0.02


def moving_run(path, dim=3, frames=4, markers=True):
    """A water block on a floor that shears to the right over time (speed grows with height)."""
    g = np.arange(5) * DX + DX / 2
    if dim == 3:
        water = np.stack(np.meshgrid(g, g[:3], np.arange(8) * DX + DX / 2, indexing="ij"), -1).reshape(-1, 3)
        floor = np.stack(np.meshgrid(np.arange(-1, 12) * DX, np.arange(-1, 4) * DX, [-DX / 2], indexing="ij"),
                         -1).reshape(-1, 3)
    else:
        water = np.stack(np.meshgrid(g, np.arange(8) * DX + DX / 2, indexing="ij"), -1).reshape(-1, 2)
        floor = np.stack(np.meshgrid(np.arange(-1, 12) * DX, [-DX / 2], indexing="ij"), -1).reshape(-1, 2)
    pos0 = np.concatenate([water, floor])
    kind = np.r_[np.zeros(len(water)), np.ones(len(floor))].astype(np.int8)
    mk = None
    if markers:
        soil = floor[floor[:, 0] > 0.12].copy()
        soil[:, -1] += DX
        mk = {"position": soil, "porosity": np.full(len(soil), 0.4), "d50": np.full(len(soil), 0.01)}
    with RunWriter(path, mode="isph", dim=dim, dx=DX, arch="cpu", config_yaml="", kind=kind, ids=np.arange(len(kind)),
                   code_version="t", markers=mk) as w:
        for i in range(frames):
            pos = pos0.copy()
            vel = np.zeros_like(pos)
            m = kind == 0
            pos[m, 0] += 0.04 * i * pos[m, -1] / 0.16
            vel[m, 0] = 0.3 * i * pos[m, -1]
            w.write_frame(0.1 * i, {"position": pos, "velocity": vel, "pressure": RHO * G * (0.16 - pos[:, -1]),
                                    "density": np.full(len(kind), RHO), "active": np.ones(len(kind), bool)})
    return path


def _grey(path):
    from PIL import Image

    return np.asarray(Image.open(path).convert("L"), dtype=float)


def test_render_pngs_have_the_asked_size_are_not_blank_and_differ_between_frames(tmp_path, offscreen):
    run = moving_run(tmp_path / "m.h5")
    proc = cli("render", run, "--field", "speed", "--frames", "0,-1", "--size", "330x250", "--out", tmp_path / "png")
    assert proc.returncode == 0, proc.stderr
    a, b = _grey(tmp_path / "png" / "speed_00000.png"), _grey(tmp_path / "png" / "speed_00003.png")
    assert a.shape == b.shape == (256, 336)  # 330 x 250 rounded up to multiples of 16
    # particles, walls and the colour bar on white: measured std 40-50 grey levels; blank would be 0
    assert a.std() > 15 and b.std() > 15
    # the block has sheared by 1.5 dx at its top and is coloured by a speed that grew from 0: measured
    # mean |difference| ~10 grey levels; identical pictures would give 0
    assert np.abs(a - b).mean() > 2

    # slices, camera presets, walls and the kind colouring all draw (in this process: faster, and safe
    # once the `offscreen` fixture has seen a test picture made in a subprocess)
    for k, extra in enumerate((["--slice", "y=0.03", "--field", "pressure"], ["--camera", "top", "--walls", "hide"],
                               ["--camera", "side", "--walls", "show", "--field", "kind"])):
        pngs, _ = render_in_process(run, "--frames", "-1", "--size", "160x128", "--out", tmp_path / f"more{k}", *extra)
        assert len(pngs) == 1 and _grey(pngs[0]).std() > 15, extra


def test_soil_markers_are_drawn_as_a_translucent_region(tmp_path, offscreen):
    from PIL import Image

    def brownish(run):
        (png,), _ = render_in_process(run, "--field", "kind", "--size", "320x240", "--frames", "0", "--out",
                                      tmp_path / run.stem)
        rgb = np.asarray(Image.open(png).convert("RGB"), dtype=int)
        # translucent brown over white is measured (198, 171, 157): light, with red well above blue; water
        # (blue), walls (grey), the white background and the opaque soil entry (160, 82, 45) of the kind
        # colour bar are not
        r, b = rgb[..., 0], rgb[..., 2]
        return int(np.count_nonzero((r - b > 25) & (r > 180)))

    with_markers = brownish(moving_run(tmp_path / "soil.h5", dim=2, frames=1))
    without = brownish(moving_run(tmp_path / "bare.h5", dim=2, frames=1, markers=False))
    # 5 markers make a 0.1 m x 0.02 m region: measured ~1600 such pixels at this view scale, none without
    assert without == 0 and with_markers > 500, (with_markers, without)


def render_in_process(run, *options):
    from taichi_sph.cli import _parser
    from taichi_sph.render import frames
    from taichi_sph.render.command import draw_frames, make_plan

    args = _parser().parse_args(["render", str(run), *map(str, options)])
    src = frames.RunSource(RunFile(run))
    try:
        return draw_frames(src, make_plan(src, args, str(run)))
    finally:
        src.close()


def test_render_movies_have_one_frame_per_chosen_frame(tmp_path, offscreen):
    import imageio_ffmpeg
    from PIL import Image

    run = moving_run(tmp_path / "m2.h5", dim=2, frames=5)
    proc = cli("render", run, "--movie", tmp_path / "m.mp4", "--no-png", "--size", "320x240", "--fps", "5")
    assert proc.returncode == 0, proc.stderr
    assert not (tmp_path / "m2_images").exists()  # --no-png
    n, secs = imageio_ffmpeg.count_frames_and_secs(str(tmp_path / "m.mp4"))
    assert n == 5 and secs == pytest.approx(1.0, abs=0.05)
    render_in_process(run, "--frames", "1:4", "--movie", tmp_path / "m.gif", "--size", "96x80")
    gif = Image.open(tmp_path / "m.gif")
    assert gif.n_frames == 3 and gif.size == (96, 80)
    assert sorted(p.name for p in (tmp_path / "m2_images").glob("*.png")) == [
        "pressure_00001.png", "pressure_00002.png", "pressure_00003.png"]


def test_render_without_opengl_says_why_in_one_line_and_writes_nothing(tmp_path, offscreen):
    """VTK asked for OSMesa where libOSMesa is missing crashes: the drawing process dies, the command
    reports it in one line with exit code 2, and writes nothing."""
    import ctypes.util

    if ctypes.util.find_library("OSMesa"):
        pytest.skip("libOSMesa is installed here, so asking for it does not make rendering impossible")
    run = moving_run(tmp_path / "m.h5", frames=2)
    env = dict(cli_env(), VTK_DEFAULT_OPENGL_WINDOW="vtkOSOpenGLRenderWindow")
    proc = subprocess.run([sys.executable, "-m", "taichi_sph.cli", "render", str(run), "--movie", str(tmp_path / "m.mp4")],
                          check=False,
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "offscreen rendering is not available" in lines[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.h5"]


def test_a_renderer_that_crashes_during_the_run_leaves_the_run_alone(tmp_path, offscreen):
    import ctypes.util

    if ctypes.util.find_library("OSMesa"):
        pytest.skip("libOSMesa is installed here, so asking for it does not make rendering impossible")
    out = tmp_path / "r.h5"
    env = dict(cli_env(), VTK_DEFAULT_OPENGL_WINDOW="vtkOSOpenGLRenderWindow")
    proc = subprocess.run([sys.executable, "-m", "taichi_sph.cli", "--config", "configs/hydrostatic.yaml", "--set",
                           "dx=0.04", "--set", "end_time=0.03", "--set", "output.every=0.01", "--set",
                           "output.images={every: 0.01}", "--out", str(out), "--no-progress"],
                          check=False, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "output.images: the renderer failed" in proc.stderr
    with RunFile(out) as rf:
        assert rf.n_frames == 4 and rf.attrs["status"] == "completed"
    assert out.with_suffix(".xdmf").exists()
    assert not list(tmp_path.glob("r_images/*.png")) and not (tmp_path / "r_images" / ".snapshots").exists()


# ---- bad input ----------------------------------------------------------------------------------

BAD = [
    ("render-missing-file", ["render", "{tmp}/nothere.h5"], ["nothere.h5", "no such run file"]),
    ("render-not-hdf5", ["render", "{tmp}/fake.h5"], ["fake.h5", "not an HDF5 file"]),
    ("render-unknown-field", ["render", "{run3}", "--field", "vorticity"], ["--field 'vorticity'", "no such field"]),
    ("render-slice-outside", ["render", "{run3}", "--slice", "y=0.5"], ["--slice y=0.5", "outside the domain"]),
    ("render-slice-bad-axis", ["render", "{run3}", "--slice", "w=0.1"], ["--slice", "axis"]),
    ("render-slice-2d", ["render", "{run2}", "--slice", "y=0.1"], ["--slice", "2D"]),
    ("render-frame-out-of-range", ["render", "{run3}", "--frames", "0,7"], ["--frames", "frame 7 out of range"]),
    ("render-frame-negative-out-of-range", ["render", "{run3}", "--frames", "-5"], ["frame -5 out of range"]),
    ("render-frames-garbage", ["render", "{run3}", "--frames", "first"], ["--frames 'first'"]),
    ("render-bad-size", ["render", "{run3}", "--size", "big"], ["--size 'big'"]),
    ("render-bad-range", ["render", "{run3}", "--range", "5,1"], ["--range '5,1'"]),
    ("render-movie-suffix", ["render", "{run3}", "--movie", "{tmp}/m.avi"], ["--movie", "m.avi", ".mp4"]),
    ("render-2d-side-camera", ["render", "{run2}", "--camera", "side"], ["--camera side", "2D"]),
    ("render-no-png-no-movie", ["render", "{run3}", "--no-png"], ["--no-png"]),
    ("plot-missing-file", ["plot", "{tmp}/nothere.h5"], ["nothere.h5"]),
    ("plot-not-hdf5", ["plot", "{tmp}/fake.h5"], ["fake.h5", "not an HDF5 file"]),
    ("plot-nothing-to-plot", ["plot", "{run3}"], ["no diagnostics or probes"]),
]


@pytest.fixture(scope="module")
def bad_inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("bad")
    moving_run(d / "run3.h5", dim=3, frames=3)
    moving_run(d / "run2.h5", dim=2, frames=3, markers=False)
    return d


@pytest.mark.parametrize("args, expect", [pytest.param(a, e, id=i) for i, a, e in BAD])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(bad_inputs, tmp_path, args, expect):
    (tmp_path / "fake.h5").write_text("not hdf5\n")
    args = [a.format(tmp=tmp_path, run3=bad_inputs / "run3.h5", run2=bad_inputs / "run2.h5") for a in args]
    before = sorted(p.name for p in bad_inputs.iterdir()), sorted(p.name for p in tmp_path.iterdir())
    proc = cli(*args, timeout=120)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    assert len(lines) == 1 and lines[0].startswith("taichi-sph: error: "), proc.stderr
    for text in expect:
        assert text in lines[0], (text, lines[0])
    assert (sorted(p.name for p in bad_inputs.iterdir()), sorted(p.name for p in tmp_path.iterdir())) == before
