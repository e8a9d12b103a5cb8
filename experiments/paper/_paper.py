"""Shared driver of the paper-reproduction scripts (experiments/paper/paper_*.py)."""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path

import numpy as np

from nsga_jax.studies import make_reference, slopes, study, write_study

FIGURES = Path("docs/figures")


def output_dir(script_doc: str, name: str) -> Path:
    """Parse ``--out`` (default experiments/out/<name>) and create the folder."""
    parser = argparse.ArgumentParser(description=script_doc)
    parser.add_argument("--out", type=Path, default=Path("experiments/out") / name)
    out = parser.parse_args().out
    out.mkdir(parents=True, exist_ok=True)
    return out


def run_study(name: str, schemes, hs, ref_h: float, ref_scheme: str, overrides: dict, out: Path,
              mode: str = "separate", max_iter_cs: int | None = None, observables=None):
    """Reference, study, CSV/PNG; copies the PNGs to docs/figures/<name>_*.png."""
    t = time.perf_counter()
    print(f"{name}: reference {ref_scheme.upper()} at h = {ref_h:g} ...", flush=True)
    reference = make_reference(name, {**overrides, "scheme": ref_scheme}, ref_h)
    rows = []
    for scheme in schemes:
        extra = {"max_iter": max_iter_cs} if (scheme == "cs" and max_iter_cs) else {}
        print(f"{name}: {scheme.upper()} at h = {', '.join(f'{h:g}' for h in hs)} ...", flush=True)
        rows += study(name, [scheme], hs, reference, {**overrides, **extra}, observables, mode=mode)
    paths = write_study(rows, out, name, reference)
    FIGURES.mkdir(parents=True, exist_ok=True)
    for key in ("convergence", "iterations", "work_precision"):
        shutil.copy(paths[key], FIGURES / f"paper_{name}_{key}.png")
    elapsed = time.perf_counter() - t
    return rows, reference, elapsed


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
           command: str) -> None:
    """Write claims.json and summary.md (the table and the paper's claims checked)."""
    order = {f"{s}:{k}": v for (s, k), v in slopes(rows).items()}
    summary = {
        "scene": name, "reference": reference.description, "command": command,
        "elapsed_s": round(elapsed, 1), "orders": order,
        "claims": [{"paper": p, "ours": o, "agrees": bool(a)} for p, o, a in claims],
    }
    (out / "claims.json").write_text(json.dumps(summary, indent=2) + "\n")
    md = [f"### {name}", "", f"`{command}` ({elapsed / 60:.1f} min on this machine); reference: "
          f"{reference.description}.", "", table(rows), "",
          "Observed orders: " + ", ".join(f"{k} {v:.2f}" for k, v in order.items()), "",
          "| the paper says | we measure | agrees |", "|---|---|---|"]
    md += [f"| {p} | {o} | {'yes' if a else 'no'} |" for p, o, a in claims]
    (out / "summary.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
