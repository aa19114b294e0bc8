"""Parameter sweeps: `taichi-sph sweep`.

    taichi-sph sweep --config X.yaml --param soil.regions[0].eps0=0.3,0.5,0.8 --param dx=0.02,0.01
    taichi-sph sweep SWEEP.yaml [--workers N | --scheduler ADDRESS]

Cases are the product of every `--param` list (a grid), or those of a sweep file (below). Each case
runs in its own process (`taichi-sph run`; Taichi's state is per process), on `--workers` local
processes at a time or on the workers of a Dask distributed cluster (`--scheduler`, optional extra
`dask`; the workers must see the same file system). Every case is validated before any runs.

In the output folder (`--out`, default out/sweep_<config name>/):

- ``cases/<case>.yaml``: the config of each case; ``runs/<case>.h5`` its run file (checkpoints, probes
  CSV beside it); ``logs/<case>.log`` what the run printed;
- ``sweep.csv`` and ``sweep.h5`` (group /table, one dataset per column): one row per case with its
  status (completed, failed, unstable, killed, interrupted), the parameter values, the metrics of the
  config's `metrics` section (metrics.py), steps, wall seconds, the run file and, for a run that did
  not complete, the cause (its last error line). The table is rewritten as each case ends;
- ``sweep.png``: each metric against the first numeric parameter (one line per combination of the
  others), when matplotlib is installed.

Re-running the same sweep skips cases whose run file is complete and holds the same config; failed
cases run again. Exit code 0 when every case completed, 1 when some did not (each recorded with its
cause), 2 for bad input (nothing run).

A sweep file (YAML):

    config: freefall.yaml          # the case file, relative to the sweep file
    out: out/freefall_sweep        # output folder (relative to the working directory)
    set: {end_time: 1.0}           # overrides for every case (dotted keys; values may be lists/maps)
    grid: {soil.regions[0].eps0: [0.3, 0.5, 0.8]}   # every combination
    cases: [{name: fine, dx: 0.005}]               # and/or a list of cases (each crossed with the grid)
"""

from __future__ import annotations

import concurrent.futures as _cf
import copy
import itertools
import json
import logging
import math
import os
import re
from pathlib import Path

import numpy as np
import yaml

from .backend import cpu_threads_per_worker
from .errors import InputError

log = logging.getLogger("taichi_sph")

STATUS_BY_EXIT = {0: "completed", 2: "failed", 3: "unstable", 130: "interrupted"}


# ---------------------------------------------------------------- command line
def add_arguments(p) -> None:
    p.add_argument("sweep_file", nargs="?", help="sweep file (YAML: config, out, set, grid, cases)")
    p.add_argument("--config", "-c", help="case file to sweep (instead of a sweep file)")
    p.add_argument("--variant", help="apply a named variant of the case file to every case (before --set and "
                                     "--param; overrides the sweep file's `variant`)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=V1,V2,...",
                   help="a swept config entry and its values (YAML scalars or flow lists); repeatable, "
                        "the cases are every combination")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a config entry in every case; repeatable")
    p.add_argument("--out", help="output folder (default: the sweep file's `out`, or out/sweep_<config>)")
    p.add_argument("--workers", type=int, help="cases run at once on this machine (default 1)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the cases on a Dask distributed cluster, e.g. tcp://host:8786")
    p.add_argument("--quiet", "-q", action="store_true", help="warnings and errors only")


def run_command(args) -> int:
    if args.quiet:
        logging.getLogger().setLevel(logging.WARNING)
    plan = plan_from_args(args)
    rows = run_sweep(plan, workers=args.workers or plan.get("workers") or 1, scheduler=args.scheduler)
    done = sum(r["status"] == "completed" for r in rows)
    log.info("%d of %d case(s) completed -> %s", done, len(rows), Path(plan["out"]) / "sweep.csv")
    return 0 if done == len(rows) else 1


# ---------------------------------------------------------------- planning
def parse_param(item: str) -> tuple[str, list]:
    """`key=v1,v2,...` -> (key, [values]); values are YAML (so `[0,1],[2,3]` gives two lists)."""
    if "=" not in item:
        raise InputError(f"--param '{item}': expected key=v1,v2,...")
    key, raw = item.split("=", 1)
    key = key.strip()
    try:
        values = yaml.safe_load(f"[{raw}]")
    except yaml.YAMLError:
        raise InputError(f"--param '{item}': values are not valid YAML") from None
    if not key or not values:
        raise InputError(f"--param '{item}': needs a key and at least one value")
    return key, values


def plan_from_args(args) -> dict:
    """The sweep as {config, raw, out, cases: [{name, params, overrides}]}, every case validated."""
    from .config.load import apply_variant, parse_overrides, read_yaml
    from .config.sweep import load_sweep_file

    if bool(args.sweep_file) == bool(args.config):
        raise InputError("sweep needs a sweep file or --config (not both)")
    grid: dict[str, list] = {}
    listed: list[dict] = [{}]
    common: dict = {}
    out = None
    workers = None
    variant, asked_by = args.variant, "--variant"
    if args.sweep_file:
        spec = load_sweep_file(args.sweep_file)
        config = Path(args.sweep_file).parent / spec.config
        out = spec.out
        workers = spec.workers
        if variant is None and spec.variant is not None:
            variant, asked_by = spec.variant, f"sweep file '{args.sweep_file}': key 'variant'"
        common = dict(spec.set or {})
        grid = {k: (v if isinstance(v, list) else [v]) for k, v in (spec.grid or {}).items()}
        if spec.cases is not None:
            listed = [dict(c) for c in spec.cases] or [{}]
    else:
        config = Path(args.config)
    for item in args.param:
        key, values = parse_param(item)
        grid[key] = values
    common.update(dict(parse_overrides(args.overrides)))
    raw = read_yaml(config)
    if variant is not None:
        apply_variant(raw, variant, asked_by)
    if args.workers is not None and args.workers < 1:
        raise InputError("--workers must be at least 1")
    out = Path(args.out or out or Path("out") / f"sweep_{config.stem}")
    if out.exists() and not out.is_dir():
        raise InputError(f"--out '{out}' is not a folder")

    cases = []
    keys = list(grid)
    for k, case in enumerate(listed):
        case = dict(case)
        label = case.pop("name", None)
        for combo in itertools.product(*(grid[key] for key in keys)):
            swept = dict(zip(keys, combo))
            params = {**case, **swept}
            # a named case is called by its name (and the grid values it is crossed with)
            name = _case_name(label, swept if label is not None else params, len(listed) > 1 and label is None, k)
            cases.append({"name": name, "params": params, "overrides": {**common, **params}})
    _unique_names(cases)
    for case in cases:
        case["config"] = _case_config(raw, case, config)
    return {"config": str(config), "variant": variant, "raw": raw, "out": str(out), "cases": cases,
            "param_keys": _param_keys(cases), "workers": workers}


def _case_name(label, params: dict, numbered: bool, k: int) -> str:
    parts = [str(label)] if label is not None else ([f"case{k}"] if numbered else [])
    for key, value in params.items():
        last = re.sub(r"\[\d+\]", "", key.split(".")[-1])
        parts.append(f"{last}-{_text(value)}")
    name = "_".join(parts) or "case"
    return re.sub(r"[^A-Za-z0-9._-]+", "-", name)[:120]


def _text(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, list):
        return "x".join(_text(v) for v in value)
    if isinstance(value, dict):
        return json.dumps(value, separators=(",", ":"))
    return str(value)


def _unique_names(cases) -> None:
    seen: dict[str, int] = {}
    for case in cases:
        n = seen.get(case["name"], 0)
        seen[case["name"]] = n + 1
        if n:
            case["name"] = f"{case['name']}-{n}"


def _param_keys(cases) -> list[str]:
    keys: list[str] = []
    for case in cases:
        keys += [k for k in case["params"] if k not in keys]
    return keys


def _case_config(raw: dict, case: dict, config_path: Path):
    """Validated Config of a case (InputError naming the case)."""
    from .config.load import load_config, set_dotted

    data = copy.deepcopy(raw)
    try:
        for key, value in case["overrides"].items():
            set_dotted(data, key, copy.deepcopy(value))
        cfg = load_config(data=data)
    except InputError as exc:
        raise InputError(f"sweep case '{case['name']}' of '{config_path}': {exc}") from None
    case["data"] = data
    return cfg


# ---------------------------------------------------------------- running
def run_sweep(plan: dict, workers: int = 1, scheduler: str | None = None) -> list[dict]:
    """Run every case not yet finished; returns the table rows (case order)."""
    from .config import resolved_yaml

    client = _dask_client(scheduler) if scheduler else None
    out = Path(plan["out"])
    for sub in ("cases", "runs", "logs"):
        (out / sub).mkdir(parents=True, exist_ok=True)
    rows: dict[str, dict] = {}
    todo = []
    for case in plan["cases"]:
        cfg = case["config"]
        case_file = out / "cases" / f"{case['name']}.yaml"
        case_file.write_text(yaml.safe_dump(case["data"], sort_keys=False, default_flow_style=None))
        spec = {"name": case["name"], "config": str(case_file.resolve()), "out": str((out / "runs" / f"{case['name']}.h5").resolve()),
                "log": str((out / "logs" / f"{case['name']}.log").resolve()), "metrics": [m.model_dump() for m in cfg.metrics]}
        if _finished(spec["out"], resolved_yaml(cfg)):
            row = collect(spec, "completed", "")
            row["skipped"] = True
            rows[case["name"]] = row
            log.info("%s: finished before, skipped", case["name"])
        else:
            todo.append(spec)
    write_table(plan, rows)
    if todo:
        log.info("%d case(s) to run (%d finished before) on %s", len(todo), len(rows),
                 f"the Dask cluster at {scheduler}" if scheduler else f"{workers} local worker(s)")
        results = _run_dask(todo, client) if client is not None else _run_local(todo, workers)
        for row in results:
            rows[row["case"]] = row
            log.info("%s: %s%s", row["case"], row["status"], f" ({row['cause']})" if row["cause"] else "")
            write_table(plan, rows)
    table = [rows[c["name"]] for c in plan["cases"]]
    write_table(plan, rows, final=True)
    return table


def _finished(run_path: str, config_yaml: str) -> bool:
    from .io.hdf5 import RunFile, RunFileError

    if not Path(run_path).is_file():
        return False
    try:
        with RunFile(run_path) as rf:
            a = rf.attrs
            return a.get("status") == "completed" and rf.config_yaml == config_yaml
    except (RunFileError, OSError, KeyError):
        return False


def _run_local(specs, workers: int):
    threads = cpu_threads_per_worker(workers)
    with _cf.ThreadPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(run_case, spec, threads) for spec in specs]
        for fut in _cf.as_completed(futures):
            yield fut.result()


def _dask_client(address: str):
    try:
        from distributed import Client
    except ImportError:
        raise InputError("--scheduler needs dask.distributed: pip install 'taichi-sph[dask]'") from None
    try:
        return Client(address, timeout="20s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(f"--scheduler '{address}': cannot connect ({exc})") from None


def _run_dask(specs, client):
    from distributed import as_completed

    try:
        futures = {client.submit(run_case, spec, None, pure=False): spec for spec in specs}
        for fut in as_completed(futures):
            spec = futures[fut]
            try:
                yield fut.result()
            except Exception as exc:  # noqa: BLE001  (a lost worker: recorded, the others go on)
                yield _row(spec, "failed", f"dask: {type(exc).__name__}: {exc}")
    finally:
        client.close()


def run_case(spec: dict, threads: int | None = None) -> dict:
    """Run one case in its own process and return its table row (metrics from its run file). Runs
    wherever it is called: a local thread or a Dask worker."""
    from .cli_process import run_cli

    env = dict(os.environ)
    env["TAICHI_SPH_PROGRESS"] = "0"
    if threads is None:
        threads = _dask_worker_threads()
    if threads is not None:
        env.setdefault("TI_CPU_MAX_NUM_THREADS", str(threads))
    res = run_cli(["run", "--config", spec["config"], "--out", spec["out"], "--no-progress"], log_path=spec["log"],
                  env=env)
    code = res.rc
    status = STATUS_BY_EXIT.get(code, "killed" if code < 0 else "failed")
    cause = "" if code == 0 else _cause(res, code)
    row = collect(spec, status, cause)
    row["process_seconds"] = res.seconds
    return row


def _dask_worker_threads() -> int | None:
    """On a Dask worker, its thread count: a case uses the CPU threads its worker was given (more
    would oversubscribe the cores shared with other workers)."""
    try:
        from distributed import get_worker

        return int(get_worker().state.nthreads)
    except (ImportError, ValueError, AttributeError):
        return None


def _cause(res, code: int) -> str:
    """Why a case did not complete: the line of its output that says so (cli_process.CliRun)."""
    text = res.failure_line()
    if code < 0:
        text = f"killed by signal {-code}" + (f"; {text}" if text else "")
    return text or f"exit code {code}"


def _row(spec, status, cause) -> dict:
    return {"case": spec["name"], "status": status, "cause": cause, "run_file": spec["out"], "metrics": {},
            "steps": math.nan, "wall_seconds": math.nan}


def collect(spec: dict, status: str, cause: str) -> dict:
    """A table row from a case's run file (metrics NaN when the file cannot be read)."""
    from .config.sweep import Metric
    from .io.hdf5 import RunFile, RunFileError
    from .metrics import compute

    row = _row(spec, status, cause)
    metrics = [Metric.model_validate(m) for m in spec["metrics"]]
    try:
        with RunFile(spec["out"]) as rf:
            a = rf.attrs
            row["steps"] = float(a.get("steps", math.nan))
            row["wall_seconds"] = float(a.get("wall_seconds", math.nan))
        row["metrics"] = compute(metrics, spec["out"])
    except (RunFileError, OSError, KeyError, ValueError) as exc:
        row["metrics"] = {m.name: math.nan for m in metrics}
        if status == "completed":
            row["status"], row["cause"] = "failed", f"run file unreadable: {exc}"
    return row


# ---------------------------------------------------------------- the table
def table_columns(plan: dict) -> list[str]:
    metrics = [m.name for m in plan["cases"][0]["config"].metrics] if plan["cases"] else []
    return ["case", "status", *plan["param_keys"], *metrics, "steps", "wall_seconds", "run_file", "cause"]


def _cells(plan: dict, row: dict, case: dict) -> dict:
    cells = {"case": row["case"], "status": row["status"], "steps": row["steps"],
             "wall_seconds": row["wall_seconds"], "run_file": row["run_file"], "cause": row["cause"]}
    for key in plan["param_keys"]:
        cells[key] = case["params"].get(key, "")
    for m in case["config"].metrics:
        cells[m.name] = row["metrics"].get(m.name, math.nan)
    return cells


def write_table(plan: dict, rows: dict, final: bool = False) -> None:
    """sweep.csv (every time), sweep.h5 and sweep.png (at the end) in the output folder."""
    import csv

    out = Path(plan["out"])
    cols = table_columns(plan)
    done = [(c, rows[c["name"]]) for c in plan["cases"] if c["name"] in rows]
    table = [_cells(plan, row, case) for case, row in done]
    tmp = out / ".sweep.csv.tmp"
    with open(tmp, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for cells in table:
            w.writerow([_csv_cell(cells.get(c, "")) for c in cols])
    os.replace(tmp, out / "sweep.csv")
    if final:
        _write_h5(plan, cols, table, out / "sweep.h5")
        try:
            plot_summary(plan, table, out / "sweep.png")
        except ImportError:
            log.warning("sweep.png not drawn: matplotlib is not installed (pip install 'taichi-sph[render]')")


def _csv_cell(value) -> str:
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value)


def _numeric(values) -> bool:
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)


def _write_h5(plan, cols, table, path: Path) -> None:
    import h5py

    tmp = path.with_name(f".{path.name}.tmp")
    with h5py.File(tmp, "w") as f:
        f.attrs["format"] = "taichi-sph-sweep"
        f.attrs["config"] = plan["config"]
        f.attrs["variant"] = plan["variant"] or ""
        f.attrs["config_yaml"] = yaml.safe_dump(plan["raw"], sort_keys=False)
        f.attrs["columns"] = json.dumps(cols)
        f.attrs["params"] = json.dumps(plan["param_keys"])
        g = f.create_group("table")
        for col in cols:
            values = [cells.get(col, "") for cells in table]
            if values and _numeric(values):
                data = np.asarray(values, dtype=float)
            else:
                data = np.asarray([_csv_cell(v) for v in values], dtype=h5py.string_dtype())
            g.create_dataset(col, data=data)
    os.replace(tmp, path)


def read_table(path) -> dict[str, np.ndarray]:
    """sweep.h5 -> {column: array} (strings as str)."""
    import h5py

    with h5py.File(path, "r") as f:
        cols = json.loads(f.attrs["columns"])
        out = {}
        for c in cols:
            ds = f["table"][c]
            out[c] = ds.asstr()[()] if ds.dtype.kind == "O" else ds[()]
        return out


def plot_summary(plan: dict, table: list[dict], path: Path) -> None:
    """Each metric against the first numeric parameter, one line per combination of the others."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    metrics = [m.name for m in plan["cases"][0]["config"].metrics] if plan["cases"] else []
    ok = [c for c in table if c["status"] == "completed"]
    if not metrics or not ok:
        return
    keys = plan["param_keys"]
    xkey = next((k for k in keys if _numeric([c.get(k) for c in ok])), None)
    fig, axes = plt.subplots(len(metrics), 1, figsize=(6.4, 2.6 * len(metrics)), squeeze=False)
    for ax, name in zip(axes[:, 0], metrics):
        if xkey is None:
            ax.bar([c["case"] for c in ok], [c.get(name, math.nan) for c in ok])
            ax.tick_params(axis="x", labelrotation=30)
        else:
            others = [k for k in keys if k != xkey]
            groups: dict[str, list] = {}
            for c in ok:
                label = ", ".join(f"{k}={_text(c.get(k))}" for k in others)
                groups.setdefault(label, []).append(c)
            for label, members in groups.items():
                members.sort(key=lambda c: c[xkey])
                ax.plot([c[xkey] for c in members], [c.get(name, math.nan) for c in members], "o-",
                        label=label or None)
            ax.set_xlabel(xkey)
            if len(groups) > 1:
                ax.legend(fontsize="small")
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"sweep of {Path(plan['config']).name}: {len(ok)} of {len(table)} case(s) completed", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
