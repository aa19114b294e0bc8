"""Pictures while a run goes (`output.images`), drawn by a separate process.

Why a separate process fed with snapshots: a long run should show pictures as it goes, yet the
simulation must never wait for drawing nor be hurt by it (VTK can crash the process that draws when
OpenGL is missing). The run saves the chosen frame's arrays to a small ``.npz`` snapshot (a few
milliseconds) and starts ``python -m taichi_sph.render`` on it at low CPU priority. The renderer
never opens the HDF5 run file, which the run keeps writing (HDF5 files are not safe to read while
another process appends without SWMR). While one renderer works, newer snapshots wait and the next
renderer takes them all; at the end of the run the remaining ones are drawn before it returns. A
renderer that fails is reported once in the log, and no more pictures are attempted.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .command import default_out_dir
from .frames import save_snapshot

log = logging.getLogger("taichi_sph")


class ImageSpooler:
    def __init__(self, images, run_path: str | Path, *, dim: int, dx: float, kind: np.ndarray, units: dict,
                 markers: np.ndarray | None = None):
        self.cfg = images
        self.run_path = Path(run_path)
        self.out_dir = default_out_dir(self.run_path)
        self.spool = self.out_dir / ".snapshots"
        self.dim, self.dx, self.kind, self.units, self.markers = dim, dx, kind, units, markers
        self.next_time = 0.0
        self.pending: list[Path] = []
        self.proc: subprocess.Popen | None = None
        self.failed = False
        self.count = 0

    def due(self, t: float) -> bool:
        return not self.failed and t >= self.next_time - 1e-9 * self.cfg.every

    def add(self, index: int, t: float, fields: dict) -> None:
        """Snapshot frame ``index`` (fields by id) and hand it to a renderer when none is busy."""
        while self.next_time <= t + 1e-9 * self.cfg.every:
            self.next_time += self.cfg.every
        self.spool.mkdir(parents=True, exist_ok=True)
        path = self.spool / f"frame_{index:05d}.npz"
        save_snapshot(path, index=index, time=t, dim=self.dim, dx=self.dx, kind=self.kind, fields=fields,
                      units=self.units, markers=self.markers, stem=self.run_path.stem)
        self.pending.append(path)
        self.count += 1
        self._poll()

    def _command(self, paths) -> list[str]:
        c = self.cfg
        cmd = [sys.executable, "-m", "taichi_sph.render", "--out", str(self.out_dir), "--field", c.field,
               "--camera", c.camera, "--walls", c.walls, "--size", f"{c.size[0]}x{c.size[1]}"]
        if c.range is not None:
            cmd += ["--range", f"{c.range[0]},{c.range[1]}"]
        return cmd + [str(p) for p in paths]

    def _poll(self, wait: float | None = None) -> None:
        if self.proc is not None:
            try:
                rc = self.proc.wait(timeout=wait) if wait is not None else self.proc.poll()
            except subprocess.TimeoutExpired:
                rc = None
            if rc is None:
                return
            self._log.seek(0)
            err = self._log.read().decode("utf-8", errors="replace")
            self._log.close()
            self.proc = None
            if rc != 0:
                self.failed = True
                lines = [ln for ln in (err or "").strip().splitlines() if ln.strip()]
                log.warning("output.images: the renderer failed (%s); the run goes on without pictures",
                            lines[-1] if lines else f"exit code {rc}")
                return
        if self.pending and not self.failed:
            paths, self.pending = self.pending, []
            env = dict(os.environ)
            self._log = tempfile.TemporaryFile()  # noqa: SIM115  (closed when the renderer has finished)
            self.proc = subprocess.Popen(self._command(paths), stdout=subprocess.DEVNULL, stderr=self._log, env=env)

    def finish(self, wait: bool = True, timeout: float = 600.0) -> None:
        """Draw what is left (wait=True), or stop a busy renderer (wait=False); remove the snapshots."""
        try:
            deadline = time.monotonic() + timeout
            while wait and not self.failed and (self.proc is not None or self.pending):
                left = deadline - time.monotonic()
                if left <= 0:
                    log.warning("output.images: the renderer did not finish in %.0f s; stopped", timeout)
                    break
                self._poll(wait=left)  # waits for the busy renderer, then starts one for what is pending
            if self.proc is not None:
                self.proc.kill()
                self.proc.wait()
                self._log.close()
                self.proc = None
        finally:
            for p in self.spool.glob("*.npz") if self.spool.exists() else ():
                p.unlink(missing_ok=True)
            if self.spool.exists() and not any(self.spool.iterdir()):
                self.spool.rmdir()
