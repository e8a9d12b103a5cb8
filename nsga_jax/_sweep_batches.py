"""One batch of a sweep: its members run together (:class:`~nsga_jax._batch.BatchRun`)
and each summarised in a row of ``sweep.csv`` (see :mod:`nsga_jax._sweep`)."""

from __future__ import annotations

import dataclasses
from typing import Any

import jax
import numpy as np

from ._batch import BatchRun, joined_records, member_solution
from ._grid import Member
from ._metrics import l1_errors
from ._monitors import RunTotals
from ._precision import cast_floats
from ._scenes.spec import make_scheme
from ._solution import Solution, float64_view
from ._sweep_build import build_batch
from ._validation import step_count


def batch_rows(batch: list[Member], padded: int, mesh, max_records: int,
               structural: tuple[str, ...] | None) -> tuple[list[dict], float, float]:
    """Run one batch of members (padded with copies of the last one to
    ``padded`` members) and summarise each real member in a row."""
    configs = [m.configured for m in batch] + [batch[-1].configured] * (padded - len(batch))
    first = configs[0]
    t_end = first.solver["t_end"]
    hs = np.asarray([c.solver["h"] for c in configs])
    n_steps = np.asarray([step_count(0.0, t_end, h) for h in hs])
    every = np.maximum(1, -(-n_steps // max_records))  # per member: at most max_records kept
    dtype = first.solver["dtype"]
    built = build_batch(batch + [batch[-1]] * (padded - len(batch)), structural)
    model, scheme = cast_floats((built.model, make_scheme(first.solver)), dtype)
    q0, v0 = built.q0.astype(dtype), built.v0.astype(dtype)
    run = BatchRun(model, scheme, 0.0, q0, v0, hs.astype(dtype), n_steps, mesh=mesh)
    totals = [RunTotals() for _ in batch]  # every step's statistics, whatever the records keep
    kept, masks = [], []
    start = 0
    for out, done in run.chunks():
        step = start + 1 + np.arange(done.shape[1])
        keep = done & ((step[None, :] % every[:, None] == 0) | (step[None, :] == n_steps[:, None]))
        cols = keep.any(axis=0)
        kept.append(out if cols.all() else jax.tree_util.tree_map(lambda x: x[:, _columns(cols)], out))
        masks.append(keep[:, cols])
        for b, member_totals in enumerate(totals):  # a member's steps are a prefix of the chunk: a view
            n = int(done[b].sum())
            member_totals.add(jax.tree_util.tree_map(lambda x: x[b, :n], out), first_step=start + 1)
        start += done.shape[1]
    mask = np.concatenate(masks, axis=1)
    stacked = None
    if mask[:len(batch)].all():  # every member keeps every column: one copy, each member's records a view of it
        joined = joined_records(kept, 0.0, q0, v0, run)
        sols = [float64_view(member_solution(model, [], 0.0, q0[b], v0[b], float(hs[b]), int(n_steps[b]), run, b,
                                             totals=totals[b], joined=joined))
                for b in range(len(batch))]
        real = jax.tree_util.tree_map(lambda x: x[:len(batch)], joined)
        stacked = float64_view(dataclasses.replace(sols[0], ts=real.t, q=real.q, v=real.v, records=real,
                                                   h=hs[:len(batch)].astype(np.float64)))
    else:
        records = jax.tree_util.tree_map(lambda *xs: np.concatenate(xs, axis=1), *kept) if len(kept) > 1 else kept[0]
        sols = [float64_view(member_solution(model, [jax.tree_util.tree_map(lambda x: x[b][mask[b]], records)], 0.0,
                                             q0[b], v0[b], float(hs[b]), int(n_steps[b]), run, b, totals=totals[b]))
                for b in range(len(batch))]
    observed = built.observables(sols, stacked)
    rows = [_row(member, sol, obs, exact) for member, sol, obs, exact in zip(batch, sols, observed, built.exact)]
    return rows, run.compile_time, run.wall_time


def _columns(cols: np.ndarray) -> slice | np.ndarray:
    """Index of the kept columns ``cols`` (bool): a slice (a view) where they
    are a prefix, as in a batch's last chunk."""
    k = int(cols.sum())
    return slice(0, k) if cols[:k].all() else cols


def _row(member: Member, sol: Solution, obs: dict[str, np.ndarray], exact) -> dict[str, Any]:
    """A member's row: its values, what the scheme did (``sol``, float64),
    its observables' (``obs``) final, smallest and largest values, and their
    errors against ``exact``."""
    config = member.configured
    st = sol.stats
    row: dict[str, Any] = {"member": member.index, **member.values}
    row.update({
        "n_steps": st["n_steps"], "result": st["result"], "failed_steps": st["failed_steps"],
        "solves_per_step_mean": st["iterations"]["linear_solves"]["mean"],
        "solves_per_step_max": st["iterations"]["linear_solves"]["max"],
        "max_penetration": st["max_penetration"],
        "max_bilateral_violation": st["max_bilateral_violation_position"],
        "max_bilateral_rate_violation": st["max_bilateral_violation_velocity"],
    })
    if config.solver.get("impacts", "end") == "instants":  # what the located impacts did
        row.update({"impacts_at_instants": st["impacts_at_instants"], "instant_fallbacks": st["instant_fallbacks"]})
    for name, y in obs.items():
        if y.ndim != 1:
            continue
        row[f"{name}_final"], row[f"{name}_min"], row[f"{name}_max"] = float(y[-1]), float(y.min()), float(y.max())
    if exact is not None:
        reference = exact(sol.ts)
        for name in config.spec.error_observables:
            if name in reference and name in obs:
                row[f"error_{name}"], row[f"abs_error_{name}"] = l1_errors(obs[name], reference[name])
    return row

__all__ = ["batch_rows"]
