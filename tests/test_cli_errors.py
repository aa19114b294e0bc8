"""Bad input on the command line (SPEC section 6): exit code 2, a one-line message on stderr that
names the offending key or file, and nothing written. Validation happens before Taichi starts, so
these subprocesses compile no kernels and finish in well under a second each."""

import json
from pathlib import Path

import pytest

HYDROSTATIC = "configs/hydrostatic.yaml"

# A minimal valid 2D case, written to tmp_path and then broken in one place per case.
GOOD_YAML = """\
mode: isph
dim: 2
dx: 0.02
end_time: 0.1
dt: 0.001
output:
  path: out/small.h5
  every: 0.05
tank:
  size: [0.2, 0.2]
water:
  - {min: [0.0, 0.0], max: [0.2, 0.1]}
"""

NO_TANK_YAML = GOOD_YAML.replace("tank:\n  size: [0.2, 0.2]\n", "")
INVALID_YAML = "dx: [0.02, 0.03\nend_time: : 0.1\n  tank: {size: [0.2\n"
LIST_YAML = "- dx: 0.02\n- end_time: 0.1\n"
TANK_3_VALUES_YAML = GOOD_YAML.replace("size: [0.2, 0.2]", "size: [0.2, 0.2, 0.2]")
BLOCK_OUTSIDE_YAML = GOOD_YAML.replace("max: [0.2, 0.1]", "max: [0.3, 0.1]")
BLOCK_EMPTY_YAML = GOOD_YAML.replace("max: [0.2, 0.1]", "max: [0.2, 0.0]")

def case(case_id, args, expect, files=None, marks=()):
    """args: CLI arguments ('{tmp}' is replaced by tmp_path; '--config hydrostatic' is added when
    no config is given and the command is `run`; '--out {tmp}/sub/run.h5' is added when no --out is
    given). expect: substrings the single error line must contain. files: name -> text written
    to tmp_path before the run."""
    return pytest.param(args, expect, files or {}, id=case_id, marks=marks)


CASES = [
    # --- config keys -------------------------------------------------------------------------
    case("unknown-top-level-key", ["--set", "foo=1"], ["'foo'", "unknown key"]),
    case("unknown-nested-key", ["--set", "isph.foo=1"], ["'isph.foo'", "unknown key"]),
    case("unknown-key-in-file", ["--config", "{tmp}/extra.yaml"], ["'wave_height'", "unknown key"],
         files={"extra.yaml": GOOD_YAML + "wave_height: 0.1\n"}),
    case("wrong-type-dx", ["--set", "dx=abc"], ["'dx'", "abc"]),
    case("dx-negative", ["--set", "dx=-0.01"], ["'dx'", "greater than 0"]),
    case("dx-zero", ["--set", "dx=0"], ["'dx'", "greater than 0"]),
    case("dx-nan", ["--set", "dx=.nan"], ["'dx'"]),
    case("end-time-negative", ["--set", "end_time=-1"], ["'end_time'", "greater than 0"]),
    case("alpha-negative", ["--set", "isph.alpha=-0.1"], ["'isph.alpha'"]),
    case("collision-distance-too-large", ["--set", "isph.collision_distance=1"],
         ["'isph.collision_distance'"]),
    case("ppe-on-failure-bad-choice", ["--set", "isph.ppe.on_failure=ignore"], ["'isph.ppe.on_failure'"]),
    case("surface-density-above-one", ["--set", "isph.surface_density=1.2"], ["'isph.surface_density'"]),
    case("ppe-type-unknown", ["--set", "isph.ppe.type=amg"], ["'isph.ppe.type'"]),
    case("pore-pressure-bound-in-isph", ["--set", "guard.max_pore_pressure=1e4"],
         ["'guard.max_pore_pressure'", "mode wcsph_biot only"]),
    case("pore-pressure-bound-negative", ["--set", "mode=wcsph_biot", "--set", "guard.max_pore_pressure=-1"],
         ["'guard.max_pore_pressure'", "greater than 0"]),
    case("obstacle-motion-velocity-length",
         ["--set", "obstacles=[{min: [0.1, 0.1], max: [0.15, 0.15], motion: {velocity: [1, 0, 0]}}]"],
         ["'obstacles[0].motion.velocity'"]),
    case("obstacle-motion-amplitude-without-period",
         ["--set", "obstacles=[{min: [0.1, 0.1], max: [0.15, 0.15], motion: {amplitude: [0.01, 0]}}]"],
         ["'obstacles[0].motion.period'"]),
    case("obstacle-motion-stop-before-start",
         ["--set", "obstacles=[{min: [0.1, 0.1], max: [0.15, 0.15], motion: {velocity: [1, 0], start: 0.2, stop: 0.1}}]"],
         ["'obstacles[0].motion.stop'"]),
    # a pore lattice dx eps^(-1/dim) beyond the kernel support (2.4 dx) has no neighbours: 2D floor 0.174
    case("eps0-below-the-pore-lattice-floor", ["--config", "configs/darcy_column.yaml", "--set",
                                               "soil.regions.0.eps0=0.1"], ["'soil.regions[0].eps0'", "0.174"]),
    case("water-porosity-below-the-floor", ["--config", "configs/darcy_column.yaml", "--set",
                                            "water.0.porosity=0.15"], ["'water[0].porosity'", "kernel support"]),
    case("start-head-in-isph", ["--set", "water.0.start_head=0.3"], ["'water[0].start_head'", "wcsph_biot"]),
    case("inside-soil-in-isph", ["--set", "water.0.inside_soil=true"], ["'water[0].inside_soil'", "wcsph_biot"]),
    case("inside-soil-without-soil", ["--config", "configs/dambreak_wcsph.yaml", "--set", "water.0.inside_soil=true"],
         ["'water[0].inside_soil'", "soil_blocks"]),
    case("inside-soil-off-the-soil", ["--config", "configs/embankment.yaml", "--variant", "geostatic",
                                      "--set", "water=[{min: [0.06, 0.0], max: [0.2, 0.08], inside_soil: true}]"],
         ["'water[0].inside_soil'", "overlaps no soil block"]),
    case("obstacle-ramp-with-oscillation",
         ["--set", "obstacles=[{min: [0.1, 0.1], max: [0.15, 0.15], motion: {amplitude: [0.01, 0], period: 1, "
          "ramp: 0.5}}]"], ["'obstacles[0].motion.ramp'", "constant velocity"]),
    case("obstacle-ramp-longer-than-half-the-motion",
         ["--set", "obstacles=[{min: [0.1, 0.1], max: [0.15, 0.15], motion: {velocity: [0.1, 0], stop: 0.5, "
          "ramp: 0.5}}]"], ["'obstacles[0].motion.ramp'", "0.25"]),
    case("water-outside-and-inside-soil", ["--config", "configs/embankment.yaml", "--variant", "geostatic",
                                           "--set", "water.0.inside_soil=true",
                                           "--set", "water.0.outside_soil=true"],
         ["'water[0].outside_soil'"]),
    case("pore-volume-with-normalised-density", ["--config", "configs/soil_column.yaml", "--set",
                                                 "wcsph.soil.pore_water=pore_volume", "--set",
                                                 "wcsph.density=normalised"],
         ["'wcsph.soil.pore_water'", "continuity"]),
    case("pore-volume-with-air", ["--config", "configs/embankment.yaml", "--variant", "dry_air", "--set",
                                  "wcsph.soil.start_from=null", "--set", "wcsph.soil.pore_water=pore_volume"],
         ["'wcsph.soil.pore_water'", "air"]),
    case("pore-water-unknown", ["--config", "configs/soil_column.yaml", "--set", "wcsph.soil.pore_water=partial"],
         ["'wcsph.soil.pore_water'"]),
    case("water-table-x-not-increasing", ["--set", "water.0.table=[[0.2, 0.1], [0.1, 0.0]]"],
         ["'water[0].table'", "increase"]),
    case("water-table-point-length", ["--set", "water.0.table=[[0.2, 0.1], [0.3]]"], ["'water[0].table[1]'"]),
    case("soil-probe-without-soil", ["--set", "probes=[{name: s, type: soil_level, box: {min: [0.1, 0.0], "
                                     "max: [0.2, 0.1]}}]"], ["'probes[0].type'", "soil_blocks"]),
    case("inflow-in-isph", ["--set", "inflow=[{min: [0.0, 0.3], max: [0.1, 0.4], rate: 0.01}]"],
         ["'inflow[0]'", "wcsph_biot"]),
    case("inflow-level-without-probe",
         ["--config", "configs/embankment.yaml", "--variant", "geostatic", "--set",
          "inflow=[{min: [0.1, 0.2], max: [0.3, 0.28], rate: 0.01, level: [[0, 0.1]]}]"],
         ["'inflow[0].level_probe'", "required"]),
    case("inflow-level-probe-unknown",
         ["--config", "configs/embankment.yaml", "--variant", "geostatic", "--set",
          "inflow=[{min: [0.1, 0.2], max: [0.3, 0.28], rate: 0.01, level: [[0, 0.1]], level_probe: gauge}]",
          # the inflow's speed asks for more than the config's pinned sound speed, a rule checked first
          "--set", "wcsph.water.sound_speed=30"],
         ["'inflow[0].level_probe'", "no water_level probe", "gauge"]),
    case("inflow-level-times",
         ["--config", "configs/embankment.yaml", "--variant", "geostatic", "--set",
          "inflow=[{min: [0.1, 0.2], max: [0.3, 0.28], rate: 0.01, level: [[1, 0.1], [0.5, 0.2]], "
          "level_probe: river}]"],
         ["'inflow[0].level'", "increase"]),
    case("inflow-rate-zero",
         ["--set", "mode=wcsph_biot", "--set", "inflow=[{min: [0.0, 0.3], max: [0.1, 0.4], rate: 0}]"],
         ["'inflow[0].rate'", "greater than 0"]),
    case("ppe-width-with-sparse-cg", ["--set", "isph.ppe.type=sparse_cg", "--set", "isph.ppe.width=40"],
         ["'isph.ppe.width'", "ell_pcg and mg_pcg only"]),
    case("ppe-f32-tolerance-unreachable", ["--set", "isph.ppe.precision=f32"], ["'isph.ppe.precision'", "f32"]),
    case("dim-4", ["--set", "dim=4"], ["'dim'"]),
    case("water-block-outside-tank", ["--config", "{tmp}/outside.yaml"], ["'water[0]'", "outside the tank"],
         files={"outside.yaml": BLOCK_OUTSIDE_YAML}),
    case("water-block-outside-tank-set", ["--set", "water.0.max=[0.5, 0.3]"], ["'water[0]'", "outside"]),
    case("water-block-max-not-above-min", ["--config", "{tmp}/empty_block.yaml"], ["'water[0]'", "max must exceed min"],
         files={"empty_block.yaml": BLOCK_EMPTY_YAML}),
    case("water-list-empty", ["--set", "water=[]"], ["'water'"]),
    case("tank-size-wrong-length", ["--config", "{tmp}/tank3.yaml"], ["'tank.size'", "needs 2 values"],
         files={"tank3.yaml": TANK_3_VALUES_YAML}),
    case("tank-size-wrong-length-set", ["--set", "tank.size=[0.4, 0.4, 0.4]"], ["'tank.size'"]),
    case("gravity-wrong-length", ["--set", "gravity=[0]"], ["'gravity'"]),
    case("tank-smaller-than-two-particles", ["--set", "dx=0.3"], ["'tank.size'"]),
    case("missing-required-tank", ["--config", "{tmp}/notank.yaml"], ["'tank'", "required key is missing"],
         files={"notank.yaml": NO_TANK_YAML}),
    case("section-given-a-value", ["--set", "tank=5"], ["'tank'"]),
    case("value-used-as-section", ["--set", "dx.foo=1"], ["'dx'"]),
    case("list-index-out-of-range", ["--set", "water.3.min=[0, 0]"], ["'water.3.min'", "out of range"]),
    case("periodic-axis-missing", ["--set", "tank.periodic=[2]"], ["'tank.periodic'", "does not exist"]),
    case("periodic-axis-twice", ["--set", "tank.periodic=[0, 0]"], ["'tank.periodic'", "twice"]),
    case("periodic-not-whole-dx", ["--set", "tank.periodic=[0]", "--set", "dx=0.0075"],
         ["'tank.size'", "whole number of dx"]),
    case("periodic-below-three-cells", ["--set", "tank.periodic=[0]", "--set", "dx=0.08"],
         ["'tank.size'", "3 neighbour-search cells"]),
    case("taylor-green-needs-periodic-box", ["--set", "water.0.initial_velocity=taylor_green"],
         ["'water[0].initial_velocity'", "periodic"]),
    # --- mode wcsph_biot keys ----------------------------------------------------------------
    case("wcsph-key-with-mode-isph", ["--set", "wcsph.xsph=0.3"], ["'wcsph.xsph'", "mode wcsph_biot only"]),
    case("wcsph-nested-key-with-mode-isph", ["--set", "wcsph.air.cohesion=10"],
         ["'wcsph.air.cohesion'", "mode wcsph_biot only"]),
    case("isph-key-with-mode-wcsph", ["--set", "mode=wcsph_biot", "--set", "isph.alpha=0.02"],
         ["'isph.alpha'", "mode isph only"]),
    case("air-with-mode-isph", ["--set", "air=[{min: [0, 0], max: [0.1, 0.1]}]"], ["'air[0]'", "wcsph_biot"]),
    case("air-block-outside-tank", ["--set", "mode=wcsph_biot", "--set", "air=[{min: [0, 0], max: [0.5, 0.1]}]"],
         ["'air[0]'", "outside the tank"]),
    case("air-block-wrong-length", ["--set", "mode=wcsph_biot", "--set", "air=[{min: [0, 0, 0], max: [1, 1, 1]}]"],
         ["'air[0].min'", "needs 2 values"]),
    case("turbulence-with-mode-wcsph", ["--set", "mode=wcsph_biot", "--set", "fluid.turbulence=smagorinsky"],
         ["'fluid.turbulence'", "isph only"]),
    case("air-inside-soil-without-soil",
         ["--set", "mode=wcsph_biot", "--set", "air=[{min: [0, 0.3], max: [0.1, 0.4], inside_soil: true}]"],
         ["'air[0].inside_soil'", "soil_blocks"]),
    case("air-in-soil-without-viscosity",
         ["--config", "configs/consolidation.yaml", "--set", "air=[{min: [0, 0.24], max: [0.05, 0.3]}]",
          "--set", "fluid.viscosity=0"], ["'wcsph.soil.air_permeability'", "viscosity"]),
    case("wcsph-xsph-above-one", ["--set", "mode=wcsph_biot", "--set", "wcsph.xsph=1.5"], ["'wcsph.xsph'"]),
    case("wcsph-density-bad-choice", ["--set", "mode=wcsph_biot", "--set", "wcsph.density=summation"],
         ["'wcsph.density'"]),
    case("wcsph-speed-factor-below-10", ["--set", "mode=wcsph_biot", "--set", "wcsph.water.speed_factor=5"],
         ["'wcsph.water.speed_factor'"]),
    case("wcsph-sound-speed-too-low", ["--set", "mode=wcsph_biot", "--set", "wcsph.water.sound_speed=3"],
         ["'wcsph.water.sound_speed'", "below 10 x the expected speed"]),
    case("wcsph-beta-max-below-one", ["--set", "mode=wcsph_biot", "--set", "wcsph.beta_max=0.5"],
         ["'wcsph.beta_max'"]),
    case("wcsph-air-gamma-zero", ["--set", "mode=wcsph_biot", "--set", "wcsph.air.gamma=0"], ["'wcsph.air.gamma'"]),
    case("wcsph-normalise-every-zero", ["--set", "mode=wcsph_biot", "--set", "wcsph.normalise_every=0"],
         ["'wcsph.normalise_every'"]),
    case("mode-unknown", ["--set", "mode=lbm"], ["'mode'"]),
    case("dt-larger-than-output-every", ["--set", "dt=0.1"], ["'output.every'"]),
    case("dt-not-below-end-time", ["--set", "end_time=0.001", "--set", "output.every=0.001"], ["'dt'"]),
    case("end-time-infinite", ["--set", "end_time=.inf", "--set", "dx=0.04"], ["'end_time'"]),
    case("end-time-boolean", ["--set", "end_time=true", "--check"], ["'end_time'"]),
    case("dx-quoted-string", ["--set", 'dx="0.01"', "--check"], ["'dx'"]),
    # --- probes and pictures ------------------------------------------------------------------
    case("probe-outside-tank", ["--set", "probes=[{name: p, type: pressure, point: [0.2, 0.5]}]"],
         ["'probes[0].point'", "outside the tank"]),
    case("probe-box-outside-tank", ["--set", "probes=[{name: v, type: water_volume, box: {min: [0, 0], max: [0.5, 0.1]}}]"],
         ["'probes[0].box'", "outside the tank"]),
    case("probe-unknown-type", ["--set", "probes=[{name: p, type: wave_height, point: [0.2, 0.1]}]"],
         ["'probes[0].type'", "wave_height"]),
    case("probe-duplicate-name", ["--set", "probes=[{name: p, type: pressure, point: [0.2, 0.1]}, "
                                  "{name: p, type: water_level, point: [0.1, 0.0]}]"],
         ["'probes[1].name'", "duplicate probe name 'p'"]),
    case("probe-velocity-column-clash", ["--set", "probes=[{name: v_x, type: pressure, point: [0.2, 0.1]}, "
                                         "{name: v, type: velocity, box: {min: [0, 0], max: [0.1, 0.1]}}]"],
         ["'probes[1].name'", "duplicate probe name 'v_x'"]),
    case("probe-missing-point", ["--set", "probes=[{name: p, type: pressure}]"], ["'probes[0].point'", "required"]),
    case("probe-point-for-box-type", ["--set", "probes=[{name: v, type: velocity, point: [0.2, 0.1]}]"],
         ["'probes[0].box'", "required"]),
    case("probe-point-wrong-length", ["--set", "probes=[{name: p, type: pressure, point: [0.2, 0.1, 0.1]}]"],
         ["'probes[0].point'", "needs 2 values"]),
    case("probe-bad-name", ["--set", "probes=[{name: 'p 1', type: pressure, point: [0.2, 0.1]}]"],
         ["'probes[0].name'"]),
    case("probe-every-below-dt", ["--set", "probes=[{name: p, type: pressure, point: [0.2, 0.1], every: 0.0001}]"],
         ["'probes[0].every'", "at least dt"]),
    case("probe-unknown-key", ["--set", "probes=[{name: p, type: pressure, point: [0.2, 0.1], radius: 1}]"],
         ["'probes[0].radius'", "unknown key"]),
    case("images-every-below-output-every", ["--set", "output.images={every: 0.01}"],
         ["'output.images.every'", "at least output.every"]),
    case("images-unknown-field", ["--set", "output.images={every: 0.1, field: vorticity}"],
         ["'output.images.field'"]),
    case("images-camera-side-in-2d", ["--set", "output.images={every: 0.1, camera: side}"],
         ["'output.images.camera'", "2D"]),
    case("images-size-three-values", ["--set", "output.images={every: 0.1, size: [100, 100, 3]}"],
         ["'output.images.size'"]),
    # --- config files ------------------------------------------------------------------------
    case("config-file-missing", ["--config", "{tmp}/nothere.yaml"], ["nothere.yaml", "does not exist"]),
    case("config-file-invalid-yaml", ["--config", "{tmp}/broken.yaml"], ["broken.yaml", "not valid YAML"],
         files={"broken.yaml": INVALID_YAML}),
    case("config-top-level-list", ["--config", "{tmp}/list.yaml"], ["list.yaml", "mapping"],
         files={"list.yaml": LIST_YAML}),
    case("config-file-empty", ["--config", "{tmp}/empty.yaml"], ["empty.yaml"], files={"empty.yaml": ""}),
    case("config-is-directory", ["--config", "{tmp}/cfgdir"], ["cfgdir"], files={"cfgdir/": None}),
    # --- command line ------------------------------------------------------------------------
    case("set-without-equals", ["--set", "dx"], ["--set 'dx'", "key=value"]),
    case("set-empty-key", ["--set", "=3"], ["--set '=3'", "empty key"]),
    case("set-invalid-yaml-value", ["--set", "dx=[0.01"], ["--set 'dx=[0.01'", "not valid YAML"]),
    case("unknown-variant", ["--variant", "nope"], ["--variant 'nope'", "not defined"]),
    case("arch-not-a-choice", ["--arch", "tpu"], ["--arch", "tpu"]),
    case("out-existing-directory", ["--out", "{tmp}/outdir"], ["--out", "outdir", "is a directory"],
         files={"outdir/": None}),
    case("out-without-h5-suffix", ["--out", "{tmp}/sub/run.txt"], ["--out", "run.txt", ".h5"]),
    case("out-parent-is-a-file", ["--out", "{tmp}/plain.txt/run.h5"], ["--out", "plain.txt", "not a directory"],
         files={"plain.txt": "not a directory\n"}),
    case("unknown-flag", ["--bogus"], ["--bogus"]),
    case("unknown-subcommand", ["frobnicate"], ["frobnicate"]),
    case("run-without-config", ["run"], ["--config"]),
    case("subcommand-not-available", ["bench"], ["bench", "not available"]),
    case("sweep-without-config", ["sweep"], ["sweep", "--config"]),
    case("sweep-bad-param", ["sweep", "--config", "configs/hydrostatic.yaml", "--param", "dx"], ["--param 'dx'"]),
    case("resume-missing-run-file", ["resume", "{tmp}/nothere.h5"], ["nothere.h5"]),
    case("metric-unknown-probe", ["--set", "metrics=[{name: m, probe: nowhere}]"], ["metrics[0].probe", "nowhere"]),
    case("checkpoint-keep-zero", ["--set", "checkpoint.keep=0"], ["checkpoint.keep"]),
    case("guard-wall-crossing-unknown", ["--set", "guard.wall_crossing=stop"], ["guard.wall_crossing"]),
    case("info-without-input", ["info"], ["info"]),
    case("info-missing-run-file", ["info", "{tmp}/nothere.h5"], ["nothere.h5"]),
    case("info-not-hdf5", ["info", "{tmp}/fake.h5"], ["fake.h5", "not an HDF5 file"],
         files={"fake.h5": "not hdf5\n"}),
]


def _snapshot(root: Path) -> dict:
    return {str(p.relative_to(root)): (p.is_dir(), None if p.is_dir() else p.stat().st_size)
            for p in root.rglob("*")}


def _expand(args, tmp_path):
    return [a.replace("{tmp}", str(tmp_path)) for a in args]


def _error_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip() and not line.startswith("[Taichi]")]


@pytest.mark.parametrize("args, expect, files", CASES)
def test_bad_input_exits_2_with_one_line_and_writes_nothing(run_cli, tmp_path, args, expect, files):
    for name, text in files.items():
        if name.endswith("/"):
            (tmp_path / name).mkdir()
        else:
            (tmp_path / name).write_text(text)
    args = _expand(args, tmp_path)
    command = args[0] if args and args[0] in ("run", "info", "render", "plot", "sweep", "resume", "bench") else "run"
    if command == "run" and "--config" not in args and args != ["run"]:
        args = [*args, "--config", HYDROSTATIC]
    if command == "run" and "--out" not in args:
        args = [*args, "--out", str(tmp_path / "sub" / "run.h5")]
    before = _snapshot(tmp_path)

    proc = run_cli(*args, timeout=120)

    lines = _error_lines(proc.stderr)
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    assert len(lines) == 1, f"expected one line on stderr, got:\n{proc.stderr}"
    assert proc.stderr.strip() == lines[0], f"stray output on stderr:\n{proc.stderr}"
    line = lines[0]
    assert line.startswith("taichi-sph: error: "), line
    assert "Traceback" not in proc.stderr + proc.stdout
    for text in expect:
        assert text in line, f"{text!r} not in {line!r}"
    assert "[Taichi]" not in proc.stdout + proc.stderr, "Taichi started before the input was validated"
    # nothing written
    assert not (tmp_path / "sub" / "run.h5").exists()
    assert not (tmp_path / "sub").exists()
    assert _snapshot(tmp_path) == before


def test_check_valid_config_writes_nothing(run_cli, tmp_path):
    out = tmp_path / "sub" / "run.h5"
    proc = run_cli("--config", HYDROSTATIC, "--check", "--out", out, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "valid" in proc.stdout
    assert "[Taichi]" not in proc.stdout + proc.stderr
    assert not out.exists()
    assert not (tmp_path / "sub").exists()
    assert list(tmp_path.iterdir()) == []


def test_check_small_config_file(run_cli, tmp_path):
    (tmp_path / "small.yaml").write_text(GOOD_YAML)
    before = _snapshot(tmp_path)
    proc = run_cli("run", "--config", tmp_path / "small.yaml", "--check", "--out", tmp_path / "sub" / "run.h5",
                   timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert _snapshot(tmp_path) == before


def test_info_config_json(run_cli, tmp_path):
    proc = run_cli("info", "--config", HYDROSTATIC, "--json", timeout=120)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert data["mode"] == "isph"
    assert data["dim"] == 2
    assert data["dx"] == pytest.approx(0.01)
    # mode isph: f64 on the CPU, f32 on a GPU unless the config says
    assert data["precision"] == {"setting": "auto", "arch": "cpu", "cpu": "f64", "gpu": "f32"}
    assert "[Taichi]" not in proc.stdout + proc.stderr


def test_info_config_json_with_override(run_cli):
    proc = run_cli("info", "--config", HYDROSTATIC, "--set", "dx=0.02", "--set", "isph.alpha=0", "--json",
                   timeout=120)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert data["dx"] == pytest.approx(0.02)
    assert data["isph"]["alpha"] == 0


def test_info_config_shows_the_precision_a_run_takes(run_cli):
    proc = run_cli("info", "--config", HYDROSTATIC, "--set", "mode=wcsph_biot", "--json", timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["precision"] == {"setting": "auto", "arch": "cpu", "cpu": "f32", "gpu": "f32"}
    proc = run_cli("info", "--config", HYDROSTATIC, "--set", "precision=f32", "--json", timeout=120)
    assert json.loads(proc.stdout)["precision"]["cpu"] == "f32"


def test_info_config_bad_override_exits_2(run_cli):
    proc = run_cli("info", "--config", HYDROSTATIC, "--set", "isph.foo=1", "--json", timeout=120)
    assert proc.returncode == 2
    lines = _error_lines(proc.stderr)
    assert len(lines) == 1 and "'isph.foo'" in lines[0], proc.stderr
    assert proc.stdout == ""


def test_config_doc_is_current():
    """docs/config.md is generated from the schema; a schema change must regenerate it."""
    import subprocess
    import sys

    from .conftest import ROOT

    r = subprocess.run([sys.executable, "tools/config_doc.py", "--check"], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


def test_sparse_cg_off_the_cpu_is_refused_before_the_run():
    """isph.ppe.type sparse_cg is f32 and unpreconditioned off the CPU (Taichi 1.7.4): a tolerance below
    f32's reach is refused with a line naming the key; on the CPU, and with a reachable tolerance, it is
    taken (tests/test_cuda.py runs the refusal through the CLI on a GPU)."""
    from taichi_sph.config.isph import PPESolver
    from taichi_sph.errors import InputError
    from taichi_sph.isph.solver import check_sparse_cg_backend

    strict = PPESolver(type="sparse_cg", tolerance=1e-8)
    with pytest.raises(InputError, match="isph.ppe.tolerance"):
        check_sparse_cg_backend(strict, cpu=False)
    check_sparse_cg_backend(strict, cpu=True)
    check_sparse_cg_backend(PPESolver(type="sparse_cg", tolerance=1e-4), cpu=False)
