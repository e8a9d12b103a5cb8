"""Writing a run to disk: trajectory (NPZ), summary (JSON), plots (PNG).

While a run is going, each finished chunk of steps is written at once to
``DIR/partial/chunk_XXXXX.npz``, so an interrupted run loses nothing already
computed. At the end ``DIR/trajectory.npz`` holds the solution's records;
when they keep every step the chunk files are deleted, else (``record_every >
1``) they are kept in ``DIR/steps/`` as the full-resolution record
(:func:`load_chunks` reads them back).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ._simulate import Solution  # noqa: E402
from .integrators.base import StepOutput  # noqa: E402

RECORD_FIELDS = ("t", "q", "v", "lam", "nu", "impulse", "gap", "bilateral", "bilateral_rate",
                 "iterations", "residual", "result")


def chunk_writer(out_dir: Path):
    """An ``on_chunk`` callback for :func:`~nsga_jax.simulate` that saves each chunk."""
    partial = Path(out_dir) / "partial"
    partial.mkdir(parents=True, exist_ok=True)

    def write(k: int, records: StepOutput) -> None:
        arrays = {f: np.asarray(getattr(records, f)) for f in RECORD_FIELDS}
        tmp = partial / f"chunk_{k:05d}.tmp.npz"
        np.savez(tmp, **arrays)
        tmp.rename(partial / f"chunk_{k:05d}.npz")

    return write


def summary(sol: Solution, scene: str, scheme: str, extra: dict[str, Any] | None = None) -> dict:
    out = {"scene": scene, "scheme": scheme}
    out.update(sol.stats)
    out["t_end"] = float(sol.ts[-1])
    if extra:
        out.update(extra)
    return out


def write_run(sol: Solution, out_dir: Path, info: dict[str, Any]) -> dict[str, Path]:
    """Write trajectory.npz, summary.json and PNG plots; returns the paths written."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {}
    arrays = {"t": sol.ts, "q": sol.q, "v": sol.v,
              "iterations": sol.iterations, "result": np.asarray(sol.records.result),
              "impulse": sol.impulse, "gap": sol.gap}
    for name, values in sol.observables.items():
        arrays[name] = values
    paths["trajectory"] = out_dir / "trajectory.npz"
    np.savez_compressed(paths["trajectory"], **arrays)
    paths["summary"] = out_dir / "summary.json"
    paths["summary"].write_text(json.dumps(info, indent=2) + "\n")
    if sol.observables:
        paths["observables_plot"] = plot_observables(sol, out_dir / "observables.png", info.get("scene", ""))
    paths["iterations_plot"] = plot_iterations(sol, out_dir / "iterations.png")
    partial = out_dir / "partial"
    if len(sol.ts) == sol.n_steps + 1:  # every step is in trajectory.npz
        shutil.rmtree(partial, ignore_errors=True)
    elif partial.exists():
        shutil.rmtree(out_dir / "steps", ignore_errors=True)
        partial.rename(out_dir / "steps")
        paths["steps"] = out_dir / "steps"
    return paths


def plot_observables(sol: Solution, path: Path, title: str = "") -> Path:
    names = [k for k, v in sol.observables.items() if np.ndim(v) == 1]
    ncols = 2 if len(names) > 1 else 1
    nrows = -(-len(names) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(6.0 * ncols, 2.3 * nrows), squeeze=False, sharex=True)
    for ax, name in zip(axes.flat, names):
        ax.plot(sol.ts, sol.observables[name], lw=1.0)
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(names):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(f"{title}  (h = {sol.h:g} s, {sol.n_steps} steps)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_iterations(sol: Solution, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(7.0, 3.0))
    it = sol.iterations
    for i, name in enumerate(("smooth", "position", "velocity")):
        ax.step(sol.ts[1:], it[1:, i] + 0.06 * (i - 1), where="post", lw=1.0, label=name)
    failed = sol.failed_steps
    if failed.size:
        ax.plot(sol.ts[failed], np.zeros(failed.size), "rx", label="failed step")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("Newton iterations")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def load_chunks(out_dir: Path, folder: str = "partial") -> dict[str, np.ndarray]:
    """Concatenate the chunk files in ``DIR/partial`` (an interrupted run) or
    ``DIR/steps`` (every step of a run with ``record_every > 1``)."""
    files = sorted((Path(out_dir) / folder).glob("chunk_?????.npz"))
    if not files:
        return {}
    parts = [dict(np.load(f)) for f in files]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


__all__ = ["chunk_writer", "write_run", "summary", "load_chunks", "plot_observables", "plot_iterations"]
