"""Shared driver of the paper-reproduction scripts (experiments/paper/paper_*.py)."""

from __future__ import annotations

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from nsga_jax import _plotting as plotting
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._studies import Reference, StudyRow, make_reference, slopes, study, write_study
from nsga_jax._tables import read_csv

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

FIGURES = Path("docs/figures")
RESULTS = Path("docs/results")
STUDY_FIELDS = ("scheme", "h", "n_steps", "batch_size", "wall_time_s", "compile_time_s", "failed_steps",
                "first_failure_t", "result")


def arguments(script_doc: str, name: str, **flags: str) -> argparse.Namespace:
    """Parse ``--out`` (default experiments/out/<name>, created) and the boolean
    ``flags`` (``fig6_only="help"`` gives ``--fig6-only``)."""
    parser = argparse.ArgumentParser(description=script_doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("experiments/out") / name)
    for flag, text in flags.items():
        parser.add_argument("--" + flag.replace("_", "-"), action="store_true", help=text)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def output_dir(script_doc: str, name: str) -> Path:
    """Parse ``--out`` (default experiments/out/<name>) and create the folder."""
    return arguments(script_doc, name).out


def run_study(name: str, schemes, hs, ref_h: float, ref_scheme: str, overrides: dict, out: Path,
              mode: str = "separate", max_iter_cs: int | None = None, observables=None, variant: str = ""):
    """Reference, study, CSV/PNG; copies the PNGs to docs/figures/paper_<name>_*.png
    (paper_<name>_<variant>_*.png for a ``variant`` of the scene, such as a finer mesh)."""
    t = time.perf_counter()
    print(f"{name}: reference {ref_scheme.upper()} at h = {ref_h:g} ...", flush=True)
    reference = make_reference(name, {**overrides, "scheme": ref_scheme}, ref_h)
    rows = []
    for scheme in schemes:
        extra = {"max_iter": max_iter_cs} if (scheme == "cs" and max_iter_cs) else {}
        print(f"{name}: {scheme.upper()} at h = {', '.join(f'{h:g}' for h in hs)} ...", flush=True)
        rows += study(name, [scheme], hs, reference, {**overrides, **extra}, observables, mode=mode)
    draw(rows, out, name, reference, variant)
    elapsed = time.perf_counter() - t
    return rows, reference, elapsed


def read_study(results_dir: Path) -> tuple[str, str, list[StudyRow], Reference]:
    """The scene, its variant, the rows and the reference of a committed study (study.csv and
    claims.json of a results folder such as docs/results/paper_bar), read back
    as written by :func:`run_study` and :func:`finish`."""
    results_dir = Path(results_dir)
    claims = json.loads((results_dir / "claims.json").read_text())
    rows = []
    for r in read_csv(results_dir / "study.csv"):
        stats = [c[: -len("_mean")] for c in r if c.endswith("_mean")]
        rows.append(StudyRow(
            **{k: r[k] for k in STUDY_FIELDS},
            iterations={s: {"mean": r[f"{s}_mean"], "max": r[f"{s}_max"]} for s in stats
                        if r[f"{s}_mean"] != ""},  # another scheme's sub-problem: blank in this row
            errors={c[len("error_"):]: float(v) for c, v in r.items() if c.startswith("error_")},
        ))
    return claims["scene"], claims.get("variant", ""), rows, Reference(description=claims["reference"])


def _wrap_orders(fig) -> None:
    """Panel titles "observed order: DS 1.28, DSN 1.87, CS 1.24, MJ 1.18" of four
    schemes are wider than a panel (they ran into the next panel and the
    legend): the orders go on a line of their own."""
    for ax in fig.axes:
        text = ax.get_title(loc="left")
        if text.startswith("observed order: "):
            ax.set_title(text.replace(": ", ":\n", 1), loc="left")


def _log_solves(fig, spread: float = 20.0) -> None:
    """Linear solves per step on a log axis when the schemes differ by more than
    ``spread`` (CS's hundreds beside DS's one to five, which a linear axis
    flattens onto zero), with the same limits in both panels."""
    axes = [ax for ax in fig.axes if "linear solves per step" in ax.get_ylabel()]
    ys = np.concatenate([np.asarray(line.get_ydata(), float) for ax in axes for line in ax.lines] or [[]])
    ys = ys[np.isfinite(ys) & (ys > 0)]
    if ys.size == 0 or ys.max() < spread * ys.min():
        return
    for ax in axes:
        ax.set_yscale("log")
        ax.set_ylim(0.8 * ys.min(), 1.5 * ys.max())
        plotting.log_ticks(ax, "y")


def figure_stem(name: str, variant: str = "") -> str:
    """paper_<name> or paper_<name>_<variant>, with the variant's spaces as underscores."""
    return f"paper_{name}" + (f"_{variant.replace(' ', '_')}" if variant else "")


def draw(rows, out: Path, name: str, reference: Reference, variant: str = "") -> dict[str, Path]:
    """study.csv and the three study figures in ``out`` (:func:`write_study`,
    with :func:`_wrap_orders` and :func:`_log_solves`), the figures copied to
    docs/figures/<:func:`figure_stem`>_*.png."""
    with plotting.capture() as figures:
        paths = write_study(rows, out, f"{name} ({variant})" if variant else name, reference)
    with plotting.style():
        _wrap_orders(figures[paths["convergence"]])
        _log_solves(figures[paths["iterations"]])
    FIGURES.mkdir(parents=True, exist_ok=True)
    for key in ("convergence", "iterations", "work_precision"):
        plotting.save(figures[paths[key]], paths[key])
        shutil.copy(paths[key], FIGURES / f"{figure_stem(name, variant)}_{key}.png")
    return paths


def replot(results_dir: Path) -> list[Path]:
    """Redraw the three study figures of a committed study from its CSV (no
    rerun) into docs/figures/paper_<scene>_*.png."""
    name, variant, rows, reference = read_study(results_dir)
    with tempfile.TemporaryDirectory() as tmp:
        draw(rows, Path(tmp), name, reference, variant)
    stem = figure_stem(name, variant)
    return [FIGURES / f"{stem}_{key}.png" for key in ("convergence", "iterations", "work_precision")]


def table(rows) -> str:
    names = list(rows[0].errors)
    head = "| scheme | h [s] | " + " | ".join(f"error {k}" for k in names) + \
        " | solves/step mean | max | wall [s] | failed steps |"
    lines = [head, "|" + "---|" * (len(names) + 6)]
    for r in rows:
        errs = " | ".join("—" if not np.isfinite(r.errors[k]) else f"{r.errors[k]:.2e}" for k in names)
        it = r.iterations["linear_solves"]
        lines.append(f"| {r.scheme.upper()} | {r.h:g} | {errs} | {it['mean']:.2f} | {it['max']} | "
                     f"{r.wall_time_s:.2f} | {r.failed_steps} |")
    return "\n".join(lines)


def finish(name: str, rows, reference, elapsed: float, claims: list[tuple[str, str, bool]], out: Path,
           command: str, variant: str = "") -> None:
    """Write claims.json and summary.md (the table and the paper's claims checked)."""
    order = {f"{s}:{k}": v for (s, k), v in slopes(rows).items()}
    summary = {
        "scene": name, "variant": variant, "reference": reference.description, "command": command,
        "elapsed_s": round(elapsed, 1), "orders": order,
        "claims": [{"paper": p, "ours": o, "agrees": bool(a)} for p, o, a in claims],
    }
    (out / "claims.json").write_text(json.dumps(summary, indent=2) + "\n")
    heading = f"### {name}" + (f" ({variant})" if variant else "")
    md = [heading, "", f"`{command}` ({elapsed / 60:.1f} min on this machine); reference: "
          f"{reference.description}.", "", table(rows), "",
          "Observed orders: " + ", ".join(f"{k} {v:.2f}" for k, v in order.items()), "",
          "| the paper says | we measure | agrees |", "|---|---|---|"]
    md += [f"| {p} | {o} | {'yes' if a else 'no'} |" for p, o, a in claims]
    (out / "summary.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
