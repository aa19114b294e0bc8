"""Command line: `taichi-sph [run] --config X.yaml [--set key=value ...] [--out RUN.h5] [--arch cpu|cuda|auto]`.

Exit codes: 0 success, 2 bad input (config, file, command line; nothing written), 3 the run went
numerically unstable (frames written so far are kept), 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

from .errors import EXIT_INPUT, InputError, InstabilityError

log = logging.getLogger("taichi_sph")


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2
        raise InputError(f"command line: {message}")


def _parser() -> argparse.ArgumentParser:
    p = _Parser(prog="taichi-sph", description="Particle simulation of water over and through porous ground.")
    sub = p.add_subparsers(dest="command", parser_class=_Parser)

    r = sub.add_parser("run", help="run a case (default)")
    r.add_argument("--config", "-c", required=True, help="YAML case file")
    r.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config entry (nested keys with dots, e.g. isph.alpha=0); repeatable")
    r.add_argument("--variant", help="apply a named variant from the config's `variants` section")
    r.add_argument("--out", help="run file (HDF5); default output.path of the config")
    r.add_argument("--arch", choices=["cpu", "cuda", "vulkan", "auto"], help="Taichi backend (default: config arch)")
    r.add_argument("--no-progress", action="store_true", help="no progress bar")
    r.add_argument("--quiet", "-q", action="store_true", help="warnings and errors only")
    r.add_argument("--check", action="store_true", help="validate the config and exit")

    i = sub.add_parser("info", help="what a run file holds, or what a config enables")
    i.add_argument("run_file", nargs="?", help="run file (HDF5)")
    i.add_argument("--config", "-c", help="YAML case file (instead of a run file)")
    i.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    i.add_argument("--variant")
    i.add_argument("--json", action="store_true", help="machine-readable output")

    from .render.command import add_arguments as _render_arguments

    rd = sub.add_parser("render", help="PNG pictures and MP4/GIF movies of a run (offscreen)")
    _render_arguments(rd)

    pl = sub.add_parser("plot", help="PNG plots of the diagnostics and probes over time")
    pl.add_argument("run_file", help="run file (HDF5)")
    pl.add_argument("--out", help="folder for the plots (default: beside the run file)")

    rs = sub.add_parser("resume", help="continue a run from its newest checkpoint")
    rs.add_argument("run_file", help="run file (HDF5) whose <run>.checkpoints/ holds a checkpoint")
    rs.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="override a config entry, e.g. end_time=5 to run on further; repeatable")
    rs.add_argument("--arch", choices=["cpu", "cuda", "vulkan", "auto"], help="Taichi backend")
    rs.add_argument("--no-progress", action="store_true", help="no progress bar")
    rs.add_argument("--quiet", "-q", action="store_true", help="warnings and errors only")

    from .sweep import add_arguments as _sweep_arguments

    sw = sub.add_parser("sweep", help="run a grid or list of cases in parallel and gather their metrics")
    _sweep_arguments(sw)

    sc = sub.add_parser("schema", help="print the JSON Schema of case files (for editors; docs/config.schema.json)")
    sc.add_argument("--out", help="write it to this file instead")

    for name in UNAVAILABLE:
        s = sub.add_parser(name, help="not available in this version")
        s.add_argument("args", nargs=argparse.REMAINDER)
    return p


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] not in SUBCOMMANDS and argv[0] not in ("-h", "--help"):
        argv.insert(0, "run")
    logging.basicConfig(level=logging.INFO, format="taichi-sph: %(message)s", stream=sys.stderr)
    try:
        args = _parser().parse_args(argv)
        if args.command is None:
            _parser().print_help()
            return EXIT_INPUT
        command = COMMANDS.get(args.command)
        if command is None:
            raise InputError(f"'{args.command}' is not available in this version")
        return command(args)
    except InputError as exc:
        print(f"taichi-sph: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except InstabilityError as exc:
        print(f"taichi-sph: unstable: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("taichi-sph: interrupted", file=sys.stderr)
        return 130


def _cmd_run(args) -> int:
    from .config import load_config

    if args.quiet:
        logging.getLogger().setLevel(logging.WARNING)
    cfg = load_config(args.config, args.overrides, args.variant)
    out = args.out or cfg.output.path
    _check_out_path(out, "--out" if args.out else "output.path")
    if args.check:
        print(f"{args.config}: valid")
        return 0
    from .run import run

    summary = run(cfg, out_path=out, arch=args.arch, progress=False if args.no_progress else None)
    drift = summary.get("volume_drift")
    log.info("done: %d steps in %.1f s (%.3g M particle-steps/s)%s -> %s", summary["steps"], summary["wall_seconds"],
             summary["mipps"], f", volume drift {drift:+.3%}" if drift is not None else "", out)
    return 0


def _cmd_resume(args) -> int:
    if args.quiet:
        logging.getLogger().setLevel(logging.WARNING)
    from .config.load import load_run_config
    from .io.checkpoint import CheckpointError, latest_checkpoint

    cfg = load_run_config(args.run_file, args.overrides)  # every check before Taichi starts
    try:
        checkpoint = latest_checkpoint(args.run_file)
    except CheckpointError as exc:
        raise InputError(str(exc)) from None
    from .run import run

    summary = run(cfg, out_path=args.run_file, arch=args.arch, progress=False if args.no_progress else None,
                  resume_from=checkpoint)
    log.info("done: %d steps in %.1f s -> %s", summary["steps"], summary["wall_seconds"], args.run_file)
    return 0


def _cmd_render(args) -> int:
    from .render.command import run_command

    return run_command(args)


def _cmd_plot(args) -> int:
    from .plot import run_command

    return run_command(args)


def _cmd_sweep(args) -> int:
    from .sweep import run_command

    return run_command(args)


def _cmd_schema(args) -> int:
    from .config.schema import json_schema

    text = json.dumps(json_schema(), indent=2) + "\n"
    if args.out is None:
        sys.stdout.write(text)
        return 0
    try:
        Path(args.out).write_text(text)
    except OSError as exc:
        raise InputError(f"--out '{args.out}': cannot be written ({exc.__class__.__name__})") from None
    return 0


def _check_out_path(out: str, key: str) -> None:
    p = Path(out)
    if p.is_dir():
        raise InputError(f"{key} '{out}' is a directory; give a file name such as run.h5")
    if p.suffix.lower() not in (".h5", ".hdf5"):
        raise InputError(f"{key} '{out}' must end in .h5 or .hdf5")
    parent = p.parent
    while not parent.exists():
        parent = parent.parent
    if parent.exists() and not parent.is_dir():
        raise InputError(f"{key} '{out}': '{parent}' is not a directory")


def _cmd_info(args) -> int:
    if args.config:
        from .config import load_config
        from .features import features

        cfg = load_config(args.config, args.overrides, args.variant)
        data = features(cfg)
    elif args.run_file:
        from .io.hdf5 import RunFile, RunFileError

        try:
            with RunFile(args.run_file) as rf:
                data = rf.summary()
                data.update(run_file_overview(rf, data))
        except RunFileError as exc:
            raise InputError(str(exc)) from None
    else:
        raise InputError("info needs a run file or --config")
    if args.json:
        print(json.dumps(data, indent=2, default=str))
    else:
        _print_tree(data)
    return 0


def run_file_overview(rf, summary: dict) -> dict:
    """What `info` adds to a run file's summary: the config in short, each probe's definition, and
    where the wall time went."""
    import yaml

    out: dict = {}
    try:
        cfg = yaml.safe_load(rf.config_yaml) or {}
    except yaml.YAMLError:
        cfg = {}
    if isinstance(cfg, dict) and cfg:
        out["config"] = {
            "description": cfg.get("description", ""),
            "end_time": cfg.get("end_time"),
            "dt": cfg.get("dt"),
            "output_every": (cfg.get("output") or {}).get("every"),
            "tank_size": (cfg.get("tank") or {}).get("size"),
            "water_blocks": len(cfg.get("water") or []),
            "obstacles": len(cfg.get("obstacles") or []),
            "probes": len(cfg.get("probes") or []),
            "images_every": ((cfg.get("output") or {}).get("images") or {}).get("every"),
        }
    group = rf.h5.get("probes")
    if group is not None:
        probes = {}
        for name, info in summary["probes"].items():
            attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in group[name].attrs.items()}
            probes[name] = {**info, **{k: (v.tolist() if hasattr(v, "tolist") else v)
                                       for k, v in attrs.items() if k != "units"}}
        out["probes"] = probes
    a = rf.attrs
    timings = {k: a[k] for k in ("status", "steps", "wall_seconds", "setup_seconds", "step_seconds", "mipps")
               if k in a}
    if "phase_seconds" in a:
        try:
            timings["phase_seconds"] = json.loads(a["phase_seconds"])
        except (TypeError, ValueError):
            pass
    out["timings"] = timings
    diag = rf.diagnostics()
    if "isolated" in diag and diag["isolated"].size:
        # water particles with no water neighbour within the support (spray, lone drops), per step
        import numpy as np

        iso = diag["isolated"].astype(np.int64)
        n_water = int(np.count_nonzero(rf.kind == 0))
        out["isolated_water"] = {"last": int(iso[-1]), "max": int(iso.max()), "mean": float(iso.mean()),
                                 "max_fraction_of_water": float(iso.max()) / max(n_water, 1)}
    return out


def _print_tree(data, indent=0):
    pad = "  " * indent
    for key, val in data.items():
        if isinstance(val, dict):
            print(f"{pad}{key}:")
            _print_tree(val, indent + 1)
        else:
            print(f"{pad}{key}: {val}")


#: subcommand -> its function (args -> exit code); the parser (`_parser`) defines each one's arguments
COMMANDS = {"run": _cmd_run, "info": _cmd_info, "render": _cmd_render, "plot": _cmd_plot, "sweep": _cmd_sweep,
            "resume": _cmd_resume, "schema": _cmd_schema}
#: subcommands the parser knows but this version does not run (tools/bench.py and tools/validate.py do)
UNAVAILABLE = ("bench", "validate")
SUBCOMMANDS = (*COMMANDS, *UNAVAILABLE)

if __name__ == "__main__":
    sys.exit(main())
