"""Writing a run to disk: trajectory (NPZ), summary (JSON), plots (PNG).

While a run is going, its kept records (every ``record_every``-th step,
``SaveAt(every=k)``) are written as they are computed to a few files
``DIR/partial/chunk_XXXXX.npz`` (:class:`~nsga_jax._chunks.RecordFiles`), so
an interrupted run loses nothing already computed
(:func:`~nsga_jax._chunks.load_chunks` reads them back). At the end
``DIR/trajectory.npz`` holds the same records and ``DIR/partial/`` is
deleted.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any, cast

import numpy as np

from . import _plotting as plotting
from ._chunks import chunk_files
from ._results import ConfigError
from ._solution import Solution


def chunk_writer(out_dir: Path):
    """An ``on_chunk`` callback for :func:`~nsga_jax.simulate` that saves each
    chunk in ``out_dir/partial`` (the run folder's layout)."""
    return chunk_files(Path(out_dir) / "partial")


def summary(sol: Solution, scene: str, scheme: str, extra: dict[str, Any] | None = None) -> dict:
    out: dict[str, Any] = {"scene": scene, "scheme": scheme}
    out.update(sol.stats)
    out["t_end"] = float(sol.ts[-1])
    if extra:
        out.update(extra)
    return out


def write_run(sol: Solution, out_dir: Path, info: dict[str, Any], *, plots: bool = True) -> dict[str, Path]:
    """Write trajectory.npz, summary.json and (``plots``) the PNG plots; returns the paths written."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {}
    arrays = {"t": sol.ts, "q": sol.q, "v": sol.v,
              "iterations": sol.iterations, "subproblems": np.asarray(sol.subproblems),
              "result": np.asarray(sol.records.result),
              "impulse": sol.impulse, "gap": sol.gap}
    for name, values in sol.observables.items():
        arrays[name] = values
    paths["trajectory"] = out_dir / "trajectory.npz"
    np.savez_compressed(paths["trajectory"], **cast(dict[str, Any], arrays))  # as in chunk_writer
    paths["summary"] = out_dir / "summary.json"
    paths["summary"].write_text(json.dumps(info, indent=2) + "\n")
    scene, scheme = info.get("scene", ""), info.get("scheme", "")
    if plots and any(np.ndim(v) == 1 for v in sol.observables.values()):
        paths["observables_plot"] = plot_observables(sol, out_dir / "observables.png", scene, scheme=scheme)
    if plots:
        paths["iterations_plot"] = plot_iterations(sol, out_dir / "iterations.png", scene, scheme=scheme)
    shutil.rmtree(out_dir / "partial", ignore_errors=True)  # its records are all in trajectory.npz
    return paths


def default_observables(sol: Solution, scene=None) -> list[str]:
    """The observables a run's plot shows: the scene's ``plotted`` selection
    (:class:`~nsga_jax.scenes.SceneSpec`), else every scalar one."""
    scalar = [k for k, v in sol.observables.items() if np.ndim(v) == 1]
    spec = plotting.scene_spec(scene)
    chosen = [k for k in (spec.plotted if spec is not None else ()) if k in scalar]
    return chosen or scalar


def _failure_times(sol: Solution) -> np.ndarray:
    """Times [s] of the failed steps (step k ends at t0 + k h)."""
    return sol.ts[0] + sol.failed_steps * sol.h


def plot_observables(sol: Solution, path: Path, scene: str = "", *, scheme: str = "",
                     names: list[str] | tuple[str, ...] | None = None) -> Path:
    """``observables.png``: one panel per observable against t [s], each
    labelled with its unit (:attr:`SceneSpec.units
    <nsga_jax.scenes.SceneSpec.units>`); a red line marks the first
    failed step.

    Args:
        sol: the run.
        path: the PNG to write.
        scene: the scene's name (units, default selection, title).
        scheme: the scheme's name, for the title.
        names: the scalar observables to show (default:
            :func:`default_observables`, the scene's ``plotted`` selection).
    """
    scalar = [k for k, v in sol.observables.items() if np.ndim(v) == 1]
    names = default_observables(sol, scene) if names is None else list(names)
    unknown = [k for k in names if k not in scalar]
    if unknown or not names:
        raise ConfigError(f"cannot plot {unknown[0] if unknown else 'no observable'!r}; "
                          f"scalar observables: {', '.join(scalar)}")
    ncols = 2 if len(names) > 1 else 1
    nrows = -(-len(names) // ncols)
    failed = _failure_times(sol)
    with plotting.style():
        fig, axes = plotting.figure(nrows, ncols, panel=(4.2, 1.9), sharex=True)
        for ax, name in zip(axes.flat, names):
            ax.plot(sol.ts, sol.observables[name], lw=1.0)
            ax.set_ylabel(plotting.label(name, plotting.observable_unit(scene, name)))
            plotting.plain_ticks(ax, "x")
            plotting.flat_limits(ax, sol.observables[name])
            for t in failed[:1]:
                ax.axvline(t, color="r", ls="--", lw=0.8, label="first failed step")
        plotting.hide_unused(axes, len(names))
        plotting.bottom_labels(axes, "t [s]")
        more = f", {failed.size} failed steps from the red line" if failed.size else ""
        fig.suptitle(plotting.title(scene, scheme, sol.h, f"observables ({sol.n_steps} steps{more})"))
    return plotting.save(fig, path)


def plot_iterations(sol: Solution, path: Path, scene: str = "", *, scheme: str = "") -> Path:
    """``iterations.png``: the Newton iterations (linear solves) of each step,
    as stairs over the step's time interval, one panel per sub-problem of the
    scheme (DS: smooth motion, position correction, velocity jump; CS: its
    coupled iteration; MJ: its one step), integer ticks; failed steps are red
    crosses along the top of each panel."""
    it = np.asarray(sol.iterations)
    names = plotting.subproblem_labels(getattr(sol, "subproblems", None), it.shape[1])
    failed = _failure_times(sol)
    top = max(1, int(it[1:].max(initial=0)))
    with plotting.style():
        fig, axes = plotting.figure(len(names), 1, panel=(7.0, 1.45), sharex=True, sharey=True)
        for i, (ax, name) in enumerate(zip(axes[:, 0], names)):
            counts = it[1:, i]
            ax.stairs(counts, np.asarray(sol.ts), baseline=None, lw=1.0)
            mean = float(counts.mean()) if counts.size else 0.0
            ax.set_title(f"{name}: mean {mean:.3g}, max {int(counts.max(initial=0))}", loc="left")
            ax.set_ylabel("iterations")
            if failed.size:
                ax.plot(failed, np.full(failed.size, 0.97), "x", color="r", ms=6, mew=1.5, clip_on=False,
                        transform=ax.get_xaxis_transform(), label="failed step")
            plotting.integer_ticks(ax, top=top)
        axes[0, 0].set_ylim(-0.03 * top - 0.2, 1.1 * top + 0.8)
        plotting.plain_ticks(axes[0, 0], "x")
        axes[-1, 0].set_xlabel("t [s]")
        more = f", {failed.size} failed: red crosses" if failed.size else ""
        fig.suptitle(plotting.title(scene, scheme, sol.h,
                                    f"Newton iterations (linear solves) per step ({sol.n_steps} steps{more})"))
    return plotting.save(fig, path)


__all__ = ["chunk_writer", "write_run", "summary", "plot_observables",
           "plot_iterations", "default_observables"]
