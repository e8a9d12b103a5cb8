"""Step-size studies: convergence (eq. 52 error against h), Newton iterations
against h, and error against run time, for any scheme on any scene.

A study runs a scene at several step sizes with one or more schemes, against
a reference of the same semi-discrete model: the exact solution where the
scene has one, else a run at a much smaller step. It returns one row per
(scheme, h) with the errors, timings, iteration statistics and failures, and
writes them as CSV and PNG (:func:`write_study`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import _plotting as plotting
from ._batch import simulate_batch
from ._first_step import LIMIT_SECONDS
from ._metrics import observed_order, relative_l1_error
from ._results import ConfigError
from ._saveat import SaveAt
from ._scenes import Scene, load_scene
from ._simulate import simulate
from ._solution import Solution
from ._tables import write_csv
from ._validation import step_count

MODES = ("grouped", "padded", "separate")


def run_step_sizes(scene: Scene, hs, mode: str = "grouped", group_ratio: float = 1.5,
                   first_step_limit: float | None = LIMIT_SECONDS) -> list[Solution]:
    """Run ``scene`` (its scheme and settings) at every step size in ``hs``.

    Modes: ``"separate"`` -- one compiled run per h (each with its own timing);
    ``"padded"`` -- all h in one ``vmap``, padded to the longest run;
    ``"grouped"`` -- ``vmap`` over groups of step sizes whose step counts are
    within ``group_ratio`` of each other (so padding wastes at most that
    factor), groups run one after the other. Failures never stop a run (they
    are recorded). Returns solutions in the order of ``hs``.
    """
    if mode not in MODES:
        raise ConfigError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    hs = [float(h) for h in hs]
    T = scene.solver["t_end"]
    if mode == "separate":
        groups = [[i] for i in range(len(hs))]
    elif mode == "padded":
        groups = [list(range(len(hs)))]
    else:
        order = sorted(range(len(hs)), key=lambda i: step_count(0.0, T, hs[i]))
        groups = []
        for i in order:
            if groups and step_count(0.0, T, hs[i]) <= group_ratio * step_count(0.0, T, hs[groups[-1][0]]):
                groups[-1].append(i)
            else:
                groups.append([i])
    out: list[Solution | None] = [None] * len(hs)
    scheme = scene.scheme()
    for group in groups:
        if len(group) == 1:
            i = group[0]
            out[i] = simulate(scene.model, scheme, 0.0, T, hs[i], scene.q0, scene.v0, throw=False,
                              observables=scene.observables, dtype=scene.solver["dtype"],
                              first_step_limit=first_step_limit)
        else:
            sols = simulate_batch(scene.model, scheme, 0.0, T, [hs[i] for i in group], scene.q0, scene.v0,
                                  observables=scene.observables, dtype=scene.solver["dtype"],
                                  first_step_limit=first_step_limit)
            for i, sol in zip(group, sols):
                out[i] = sol
    return out  # type: ignore[return-value]


@dataclass
class Reference:
    """A reference solution: ``values(ts)`` gives each observable at the times ``ts``."""

    description: str
    exact: Callable[[np.ndarray], dict[str, np.ndarray]] | None = None
    solution: Solution | None = None
    wall_time: float = 0.0

    def values(self, ts: np.ndarray, names) -> dict[str, np.ndarray]:
        if self.solution is None:
            assert self.exact is not None  # a reference is a solution or an exact one
            ex = self.exact(ts)
            return {k: ex[k] for k in names}
        ref = self.solution
        out = {}
        for k in names:
            y = ref.observables[k]
            ratio = np.rint(ts / ref.h).astype(int)
            if np.allclose(ratio * ref.h, ts, rtol=0, atol=1e-9 * max(1.0, ts[-1])) and ratio[-1] < len(y):
                out[k] = y[ratio]  # on the reference grid
            else:
                out[k] = np.interp(ts, ref.ts, y)
        return out


def make_reference(scene_name: str, overrides: dict, ref: str | float,
                   first_step_limit: float | None = LIMIT_SECONDS) -> Reference:
    """``ref="exact"`` (the scene's exact solution) or a step size: a run of the
    scene with ``overrides`` (which fix its scheme) at that step."""
    if ref == "exact":
        scene = load_scene(scene_name, overrides)
        if scene.exact is None:
            raise ConfigError(f"scene {scene_name!r} has no exact solution; give a reference step (--ref-h)")
        return Reference("exact solution", exact=scene.exact)
    h_ref = float(ref)
    scene = load_scene(scene_name, {**overrides, "h": h_ref})
    t = time.perf_counter()
    sol = scene.run(throw=False, progress=False, saveat=SaveAt(), dtype="float64",  # every step, in full precision
                    first_step_limit=first_step_limit)
    wall = time.perf_counter() - t
    if sol.stats["failed_steps"]:
        raise ConfigError(f"the reference run ({scene.solver['scheme']}, h = {h_ref:g}) has failed steps; "
                          "choose a smaller reference step or another scheme")
    return Reference(f"{scene.solver['scheme'].upper()} at h = {h_ref:g} s", solution=sol, wall_time=wall)


def check_reference(reference: Reference, names, t_end: float, h: float) -> None:
    """Refuse a reference on which eq. 52 is undefined for an observable (it
    is zero at every time of the study), before the study runs."""
    ts = np.arange(step_count(0.0, t_end, h) + 1) * h
    values = reference.values(ts, names)
    for k in names:
        if not np.any(np.abs(np.asarray(values[k])) > 0.0):
            raise ConfigError(f"the reference ({reference.description}) of observable {k!r} is zero at every time "
                              "of the study, so its eq. 52 error is undefined; choose other observables "
                              "(--observables) or another setup")


@dataclass
class StudyRow:
    scheme: str
    h: float
    n_steps: int
    wall_time_s: float
    compile_time_s: float
    failed_steps: int
    first_failure_t: float
    result: str
    iterations: dict
    errors: dict = field(default_factory=dict)
    batch_size: int = 1
    impacts: str = "end"
    """Where impacts were applied: ``"end"`` (the paper's step) or ``"instants"``."""
    impacts_at_instants: int = 0
    instant_fallbacks: int = 0

    def flat(self) -> dict:
        row = {"scheme": self.scheme, "h": self.h, "n_steps": self.n_steps, "batch_size": self.batch_size,
               "wall_time_s": self.wall_time_s,
               "compile_time_s": self.compile_time_s, "failed_steps": self.failed_steps,
               "first_failure_t": self.first_failure_t, "result": self.result}
        if self.impacts == "instants":
            row.update(impacts=self.impacts, impacts_at_instants=self.impacts_at_instants,
                       instant_fallbacks=self.instant_fallbacks)
        for sub, st in self.iterations.items():
            row[f"{sub}_mean"] = st["mean"]
            row[f"{sub}_max"] = st["max"]
        for k, e in self.errors.items():
            row[f"error_{k}"] = e
        return row


def study(scene_name: str, schemes, hs, reference: Reference, overrides: dict | None = None,
          observables=None, mode: str = "grouped",
          first_step_limit: float | None = LIMIT_SECONDS) -> list[StudyRow]:
    """Run ``scene_name`` with each scheme at each h; errors (eq. 52) against ``reference``.

    With a batched ``mode``, runs that shared a ``vmap`` report the batch's wall
    time (``batch_size`` says how many shared it); ``mode="separate"`` gives
    each run its own timing, as error-against-run-time plots need.

    A run that fails is kept: its errors are computed over the steps before
    its first failure only if it has none (else they are NaN), and the row
    records the failure. ``first_step_limit`` [s] is each run's and batch's
    (:func:`~nsga_jax._first_step.check_first_step`; ``None``: no limit).
    """
    overrides = dict(overrides or {})
    base = load_scene(scene_name, overrides)
    check_reference(reference, list(observables or base.spec.error_observables), base.solver["t_end"], max(hs))
    rows = []
    for scheme in schemes:
        scene = load_scene(scene_name, {**overrides, "scheme": scheme})
        names = list(observables or scene.spec.error_observables)
        sols = run_step_sizes(scene, hs, mode=mode, first_step_limit=first_step_limit)
        for sol in sols:
            st = sol.stats
            failed = sol.failed_steps
            errors = {}
            if failed.size == 0:
                ref = reference.values(sol.ts, names)
                errors = {k: relative_l1_error(sol.observables[k], ref[k]) for k in names}
            else:
                errors = {k: math.nan for k in names}
            rows.append(StudyRow(
                scheme=scheme, h=sol.h, n_steps=sol.n_steps, wall_time_s=sol.wall_time,
                compile_time_s=sol.compile_time, failed_steps=int(failed.size),
                first_failure_t=float(sol.ts[failed[0]]) if failed.size else math.nan,
                result=st["result"], iterations=st["iterations"], errors=errors,
                batch_size=sum(s.wall_time == sol.wall_time and s.compile_time == sol.compile_time for s in sols),
                impacts=scene.solver.get("impacts", "end"), impacts_at_instants=int(st["impacts_at_instants"]),
                instant_fallbacks=int(st["instant_fallbacks"]),
            ))
    return rows


def slopes(rows: list[StudyRow]) -> dict[tuple[str, str], float]:
    """Observed order of each (scheme, observable) over its converged runs."""
    out = {}
    for scheme in dict.fromkeys(r.scheme for r in rows):
        mine = [r for r in rows if r.scheme == scheme and r.failed_steps == 0]
        for k in mine[0].errors if mine else []:
            pts = [(r.h, r.errors[k]) for r in mine if np.isfinite(r.errors[k]) and r.errors[k] > 0]
            if len(pts) >= 2:
                out[(scheme, k)] = observed_order(*zip(*pts))
    return out


def write_study(rows: list[StudyRow], out_dir: Path, title: str, reference: Reference, *,
                plots: bool = True) -> dict[str, Path]:
    """study.csv and, with ``plots``, convergence.png (error vs h with slopes), iterations.png (mean and
    max linear solves per step vs h, failures marked) and work_precision.png
    (error vs wall time [s], joined in the order of h). ``title`` names the
    scene; every figure's title adds the schemes and the range of h [s].

    Each scheme keeps one marker, line style and marker size in every plot
    (:data:`~nsga_jax._plotting.SCHEME_STYLE`), so that schemes with identical
    results (DS, DSn and CS often are) stay visible on top of each other.
    Failed runs are red crosses at the bottom of the error axes."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {"csv": out_dir / "study.csv"}
    write_csv(paths["csv"], [r.flat() for r in rows])
    if not plots:
        return paths
    schemes = list(dict.fromkeys(r.scheme for r in rows))
    names = list(rows[0].errors)
    order = slopes(rows)
    styles = {s: plotting.scheme_style(s, i) for i, s in enumerate(schemes)}
    hs = sorted({r.h for r in rows})
    ncols = min(2, max(1, len(names)))
    nrows = -(-max(1, len(names)) // ncols)

    def heading(what: str) -> str:
        return plotting.title(title, schemes, hs, what)

    def mark_failures(ax, stat=None) -> None:
        """Red crosses for failed runs: at the value ``stat`` of the linear
        solves, else (no error to show) along the bottom of the axes."""
        for k, s in enumerate(schemes):
            bad = [r for r in rows if r.scheme == s and r.failed_steps]
            if bad:
                y = [r.iterations["linear_solves"][stat] for r in bad] if stat else [0.0] * len(bad)
                ax.plot([r.h for r in bad], y, "x", color="r", ms=9 - 1.5 * k, mew=1.6, clip_on=False,
                        transform=ax.transData if stat else ax.get_xaxis_transform(), label=f"{s.upper()} failed")

    with plotting.style():
        fig, axes = plotting.figure(nrows, ncols, panel=(4.2, 3.2))
        for ax, k in zip(axes.flat, names):
            for s in schemes:
                pts = [(r.h, r.errors[k]) for r in rows if r.scheme == s and np.isfinite(r.errors[k])]
                if pts:
                    ax.loglog(*zip(*sorted(pts)), label=s.upper(), **styles[s])
            mark_failures(ax)
            ax.set_xscale("log")
            plotting.log_ticks(ax, "x", hs)
            plotting.log_ticks(ax, "y")
            ax.set_xlabel("h [s]")
            ax.set_ylabel(plotting.label(f"error of {k} (eq. 52)", ""))
            fitted = ", ".join(f"{s.upper()} {order[(s, k)]:.2f}" for s in schemes if (s, k) in order)
            ax.set_title(f"observed order: {fitted}" if fitted else "no observed order", loc="left")
        plotting.hide_unused(axes, len(names))
        plotting.figure_legend(fig, axes)
        fig.suptitle(heading(f"convergence against the {reference.description}"))
    paths["convergence"] = plotting.save(fig, out_dir / "convergence.png")

    top = max(r.iterations["linear_solves"]["max"] for r in rows)
    with plotting.style():
        fig, axes = plotting.figure(1, 2, panel=(4.2, 3.2))
        for ax, stat in zip(axes[0], ("mean", "max")):
            for s in schemes:
                mine = sorted((r for r in rows if r.scheme == s), key=lambda r: r.h)
                ax.plot([r.h for r in mine], [r.iterations["linear_solves"][stat] for r in mine],
                        label=s.upper(), **styles[s])
            mark_failures(ax, stat)
            ax.set_xscale("log")
            plotting.log_ticks(ax, "x", hs)
            ax.set_xlabel("h [s]")
            ax.set_ylabel(f"{stat} linear solves per step")
            ax.set_ylim(0.0, 1.05 * top + 0.5)
        plotting.integer_ticks(axes[0, 1], top=top)
        plotting.figure_legend(fig, axes)
        fig.suptitle(heading("Newton iterations (linear solves) per step"))
    paths["iterations"] = plotting.save(fig, out_dir / "iterations.png")

    shared = any(r.batch_size > 1 for r in rows)
    with plotting.style():
        fig, axes = plotting.figure(nrows, ncols, panel=(4.2, 3.2))
        for ax, k in zip(axes.flat, names):
            for s in schemes:
                mine = sorted((r for r in rows if r.scheme == s and np.isfinite(r.errors[k])), key=lambda r: -r.h)
                if mine:  # joined in the order of decreasing h (increasing work)
                    ax.loglog([r.wall_time_s for r in mine], [r.errors[k] for r in mine], label=s.upper(),
                              **styles[s])
            plotting.log_ticks(ax, "x")
            plotting.log_ticks(ax, "y")
            ax.set_xlabel("wall time, compile excluded [s]")
            ax.set_ylabel(plotting.label(f"error of {k} (eq. 52)", ""))
        plotting.hide_unused(axes, len(names))
        plotting.figure_legend(fig, axes)
        note = " (batched runs share their batch's wall time)" if shared else ""
        fig.suptitle(heading(f"error against run time{note}"))
    paths["work_precision"] = plotting.save(fig, out_dir / "work_precision.png")
    return paths
