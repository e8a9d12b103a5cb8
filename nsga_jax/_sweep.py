"""Parameter and step-size sweeps of a scene: :func:`sweep` and ``nsga-jax sweep``.

The members of a sweep are every combination of the swept values (float scene
parameters, and step sizes). They share the scene's structure, so they run in
batches through one compiled program (:class:`~nsga_jax._batch.BatchRun`:
``vmap``, split over every device by ``shard_map`` when there are several).
Each finished batch is written at once to ``DIR/batches/batch_XXXXX.csv``;
a sweep started again in the same directory skips the batches already there,
so an interrupted sweep resumes where it stopped and loses nothing already
computed. At the end ``DIR/sweep.csv`` holds one row per member (in grid
order) and ``DIR/sweep.png`` plots the main columns against the swept values.

Each row has the member's parameters and h, what the scheme did (steps,
result, failed steps, linear solves per step, largest penetration and
bilateral violations, over every step; with ``impacts = "instants"`` the
impacts located at their instants and the steps that fell back), the final value, minimum and maximum
of each scalar observable, and, where the scene has an exact solution, the
eq. 52 error of its observables (on the recorded steps, at most
``max_records`` per member).
"""

from __future__ import annotations

import csv
import json
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import numpy as np

from ._batch import member_mesh
from ._distributed import agree
from ._first_step import LIMIT_SECONDS
from ._grid import MAX_MEMBERS, Member, members, parse_grid, parse_values  # noqa: F401  (the sweep's grid)
from ._results import ConfigError
from ._scenes import configure
from ._sweep_batches import batch_rows
from ._sweep_build import split_batches, traced_structure
from ._sweep_checks import check_batches
from ._tables import read_csv, write_csv

MEMORY_BUDGET = 2**25
"""Recorded numbers a batch keeps in memory (256 MiB in float64); the default
batch size follows from it and the model's size."""

PROCESS_COLUMNS = ("n_steps", "result", "failed_steps", "solves_per_step_mean", "solves_per_step_max",
                   "max_penetration", "max_bilateral_violation", "max_bilateral_rate_violation")


# ----------------------------------------------------------------- the grid


def default_batch_size(n_dof: int, max_records: int, n_devices: int) -> int:
    """Members per batch: a power of two (at least the device count, at most
    1024) keeping about :data:`MEMORY_BUDGET` recorded numbers."""
    fit = MEMORY_BUDGET // (max_records * (2 * n_dof + 16))
    size = 2 ** int(math.floor(math.log2(max(fit, 1))))
    return int(max(n_devices, min(1024, size)))


# ------------------------------------------------------------------- result


@dataclass
class SweepResult:
    """The sweep's table (one dict per member, in grid order) and its files."""

    rows: list[dict[str, Any]]
    swept: list[str]
    path: Path | None = None
    plot: Path | None = None
    compile_time: float = 0.0
    wall_time: float = 0.0
    files: list[Path] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    """Notes on the members' models found before the sweep ran (redundant
    bilateral constraints, :func:`~nsga_jax._run_inputs.redundancy_notes`),
    each once; also warned."""

    def column(self, name: str) -> np.ndarray:
        return np.asarray([r[name] for r in self.rows])

    @property
    def failed(self) -> list[dict[str, Any]]:
        """The rows of runs with failed steps (Newton cap or non-finite
        residual; ``result`` names the first failure)."""
        return [r for r in self.rows if r["failed_steps"]]


# ------------------------------------------------------------------ the sweep


def sweep(
    scene: str | Path,
    grid: dict[str, Sequence[float]] | dict[str, np.ndarray],
    *,
    hs: Sequence[float] | np.ndarray | None = None,
    overrides: dict[str, Any] | None = None,
    out: str | Path | None = None,
    batch_size: int | None = None,
    devices: Sequence[jax.Device] | None = None,
    max_records: int = 2000,
    progress: bool = False,
    on_batch: Callable[[int, list[dict]], None] | None = None,
    plots: bool = True,
    first_step_limit: float | None = LIMIT_SECONDS,
) -> SweepResult:
    """Run ``scene`` for every combination of the ``grid``'s values (and of ``hs``).

    Args:
        scene: a built-in scene name or a TOML config.
        grid: ``{parameter: values}`` over float scene parameters (``"h"`` too).
        hs: step sizes [s] (default: the scene's h).
        overrides: fixed config values for every member.
        out: directory of the batch files, the table and the plot; a sweep
            started again there resumes (the directory must hold the same sweep).
            With several processes (:mod:`nsga_jax._distributed`) process 0
            writes the files and decides which batches a resumed sweep skips;
            the other processes' results hold the rows they ran or can read.
        batch_size: members per compiled batch (default: from the model's size,
            :func:`default_batch_size`); rounded up to a multiple of the devices.
        devices: the devices the members are split over (default: all of them;
            one device means no sharding).
        max_records: recorded steps kept per member for observables and errors.
        progress: a progress bar over batches on stderr.
        on_batch: called as ``on_batch(k, rows)`` after batch k is written.
        plots: write ``sweep.png`` beside ``sweep.csv`` (with ``out``).
        first_step_limit: refuse, before any batch is compiled, a sweep whose
            batch's first step (its members' dense factorisations, counted one
            after another) is estimated above this many seconds
            (:func:`~nsga_jax._first_step.check_first_step`); ``None`` runs anyway.
    """
    if isinstance(max_records, bool) or not isinstance(max_records, (int, np.integer)) or max_records < 1:
        raise ConfigError(f"max_records must be an integer >= 1, got {max_records!r}")
    devices = jax.devices() if devices is None else list(devices)
    if not devices:
        raise ConfigError("devices must name at least one device")
    mems = members(scene, grid, hs, overrides, progress)
    swept = [k for k in mems[0].values]
    mesh = member_mesh(devices) if len(devices) > 1 else None
    n_dev = len(devices)
    if batch_size is None:
        batch_size = default_batch_size(mems[0].scene.model.n_dof, max_records, n_dev)
    if isinstance(batch_size, bool) or not isinstance(batch_size, (int, np.integer)) or batch_size < 1:
        raise ConfigError(f"batch_size must be an integer >= 1, got {batch_size!r}")
    batch_size = min(int(batch_size), len(mems))
    padded = -(-batch_size // n_dev) * n_dev
    structural = traced_structure(mems)
    batches = split_batches(mems, batch_size, structural)
    n_batches = len(batches)
    per_device = padded if devices[0].platform == "cpu" else padded // n_dev  # host devices share one memory
    notes = check_batches(batches, per_device, first_step_limit)  # before any batch is compiled

    out_dir = None if out is None else Path(out)
    if out_dir is not None:
        _claim(out_dir, scene, grid, hs, overrides, batch_size, len(mems), max_records)
    result = SweepResult(rows=[], swept=swept, warnings=notes)
    t_start = time.perf_counter()
    for k in range(n_batches):
        batch = batches[k]
        path = None if out_dir is None else out_dir / "batches" / f"batch_{k:05d}.csv"
        if agree(path is not None and path.exists()):  # process 0 decides: every process skips or runs it
            assert path is not None  # every process gives the same out
            rows = _read_batch(path, batch) if path.exists() else []
        else:
            rows, compile_time, wall = batch_rows(batch, padded, mesh, max_records, structural)
            result.compile_time += compile_time
            result.wall_time += wall
            for r in rows:
                r["batch"], r["batch_wall_s"] = k, wall
            if path is not None and jax.process_index() == 0:
                write_csv(path, rows)
            if on_batch is not None:
                on_batch(k, rows)
        result.rows.extend(rows)
        if progress:
            _progress(k + 1, n_batches, len(result.rows), len(mems), time.perf_counter() - t_start)
    if out_dir is not None and jax.process_index() == 0:
        result.path = out_dir / "sweep.csv"
        write_csv(result.path, result.rows)
        result.plot = plot_sweep(result, out_dir / "sweep.png") if plots else None
    return result


def _claim(out_dir: Path, scene, grid, hs, overrides, batch_size: int, n: int, max_records: int) -> None:
    """Write ``DIR/sweep.json`` describing the sweep, or check that the one
    there describes the same sweep (else resuming would mix two sweeps),
    naming every setting that differs.

    Process 0 alone reads and writes it, and every process raises if it holds
    another sweep or cannot be read (:func:`~nsga_jax._distributed.agree`): no
    process reads a half-written file, and none goes on into batches the
    others refused."""
    spec = {"scene": str(scene), "grid": {k: [float(x) for x in np.atleast_1d(v)] for k, v in grid.items()},
            "hs": None if hs is None else [float(h) for h in np.atleast_1d(hs)],
            "overrides": {k: v for k, v in (overrides or {}).items()}, "batch_size": batch_size, "members": n,
            "max_records": max_records}
    manifest = out_dir / "sweep.json"
    problem = ""
    if jax.process_index() == 0:
        if manifest.exists():
            try:
                found = json.loads(manifest.read_text())
                if not isinstance(found, dict):
                    raise ValueError("not a JSON object")
            except (ValueError, UnicodeDecodeError) as err:
                problem = (f"{manifest} cannot be read ({err}): the folder's sweep is unknown; remove the "
                           "folder (or choose another) to start afresh")
            else:
                wanted = json.loads(json.dumps(spec))
                differ = [k for k in sorted(set(wanted) | set(found)) if wanted.get(k) != found.get(k)]
                if differ:
                    listed = "; ".join(f"{k}: {found.get(k)!r} there, {wanted.get(k)!r} now" for k in differ)
                    problem = (f"{out_dir} holds another sweep ({manifest}), which a resume would mix with this "
                               f"one; they differ in {listed}. Use another folder, or remove it")
        elif any((out_dir / "batches").glob("batch_*.csv")):
            problem = (f"{out_dir / 'batches'} holds batch files but {manifest.name} is missing: whose sweep they "
                       "are is unknown, and a resume would mix them with this one; remove them or choose another "
                       "folder")
        else:
            (out_dir / "batches").mkdir(parents=True, exist_ok=True)
            manifest.write_text(json.dumps(spec, indent=2) + "\n")
    if not agree(not problem):
        raise ConfigError(problem or f"{out_dir} holds another sweep, or its {manifest.name} cannot be read "
                                     "(process 0 says why)")


def _read_batch(path: Path, batch: list[Member]) -> list[dict]:
    """A finished batch's rows, checked against the members it must hold: a
    truncated, empty or foreign batch file is a named error, never a shorter
    table."""
    try:
        rows = read_csv(path)
    except (OSError, UnicodeDecodeError, csv.Error) as err:
        raise ConfigError(f"batch file {path} cannot be read ({err}); delete it to run that batch again") from None
    members_there = [r.get("member") for r in rows]
    expected = [m.index for m in batch]
    if members_there != expected:
        raise ConfigError(f"batch file {path} holds runs {members_there[:5]}{'...' if len(rows) > 5 else ''} "
                          f"({len(rows)} rows), where this sweep's batch holds runs {expected[0]}..{expected[-1]} "
                          f"({len(expected)} rows): it is incomplete or from another sweep; delete it to run that "
                          "batch again")
    for r, m in zip(rows, batch):
        if r.get("result") in (None, "") or any(r.get(k) in (None, "") for k in m.values):
            raise ConfigError(f"batch file {path} has an incomplete row (run {r.get('member')}); delete it to "
                              "run that batch again")
        differ = [k for k, v in m.values.items() if not math.isclose(float(r[k]), v, rel_tol=1e-12, abs_tol=0.0)]
        if differ:
            raise ConfigError(f"batch file {path}: run {m.index} has {differ[0]} = {r[differ[0]]} there, "
                              f"{m.values[differ[0]]} in this sweep: it is another sweep's; delete it to run that "
                              "batch again")
    return rows


def _progress(done: int, total: int, members_done: int, members: int, elapsed: float) -> None:
    width = 30
    filled = int(width * done / total)
    eta = elapsed / done * (total - done)
    print(f"\r  [{'#' * filled}{'.' * (width - filled)}] batch {done}/{total}, {members_done}/{members} runs, "
          f"{elapsed:.0f} s, about {eta:.0f} s left", end="\n" if done == total else "", file=sys.stderr, flush=True)


# -------------------------------------------------------------------- plots


def summary_columns(result: SweepResult, scene=None) -> list[str]:
    """The columns :func:`plot_sweep` shows: errors, solves per step,
    penetration and the final values of the first four observables of the
    scene's plotted selection (:class:`~nsga_jax.scenes.SceneSpec`
    ``plotted``; without a scene, the first four)."""
    from ._plotting import scene_spec

    cols = list(result.rows[0])
    errors = [c for c in cols if c.startswith("error_")]
    finals = [c for c in cols if c.endswith("_final")]
    spec = scene_spec(scene)
    chosen = [f"{k}_final" for k in (spec.plotted if spec is not None else ()) if f"{k}_final" in finals]
    return errors + ["solves_per_step_mean", "max_penetration"] + (chosen or finals)[:4]


def plot_sweep(result: SweepResult, path: Path, scene=None, scheme: str | None = None) -> Path:
    """``sweep.png``: the :func:`summary_columns` against one swept value, one
    line per combination of the other swept values (see
    :func:`nsga_jax._sweep_plot.sweep_figure`), axes in the scene's units.

    ``scene`` (a name or config) and ``scheme`` name the units and the title;
    by default they are read from ``sweep.json`` beside ``path``, which
    :func:`sweep` writes."""
    from . import _plotting as plotting
    from ._sweep_plot import sweep_figure

    path = Path(path)
    overrides: dict[str, Any] = {}
    manifest = path.parent / "sweep.json"
    if scene is None and manifest.exists():
        described = json.loads(manifest.read_text())
        scene, overrides = described.get("scene"), described.get("overrides") or {}
    loaded = None
    if scene is not None:
        try:
            loaded = configure(scene, overrides)
        except ConfigError:
            pass
    if scheme is None:
        scheme = loaded.solver["scheme"] if loaded is not None else ""
    spec = loaded.spec if loaded is not None else scene
    fig = sweep_figure(result, summary_columns(result, spec), spec, scheme)
    return plotting.save(fig, path)
