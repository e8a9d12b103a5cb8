"""The figure of a sweep (``sweep.png``): its main columns against one swept
value, one line per combination of the other swept values."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ._plotting import (
    figure,
    figure_legend,
    hide_unused,
    label,
    log_ticks,
    observable_unit,
    parameter_unit,
    scene_spec,
    style,
    title,
)

MAX_LINES = 8
"""The most lines a sweep panel joins; more groups are drawn as markers only."""

_COUNTS = {
    "solves_per_step_mean": "mean linear solves per step",
    "solves_per_step_max": "max linear solves per step",
    "n_steps": "steps",
    "failed_steps": "failed steps",
    "impacts_at_instants": "impacts located at their instants",
    "instant_fallbacks": "steps that fell back to the paper's step",
    "max_penetration": "max penetration [m]",
    "max_bilateral_violation": "max bilateral violation (constraint units)",
    "max_bilateral_rate_violation": "max bilateral rate violation (constraint units / s)",
    "batch_wall_s": "batch wall time [s]",
}


def column_label(column: str, scene=None) -> str:
    """The axis label of a sweep column: errors ``[-]``, counts by what they
    count, penetration ``[m]``, observables and swept values in their units."""
    if column.startswith("abs_error_"):
        name = column[len("abs_error_"):]
        return label(f"largest error of {name}", observable_unit(scene, name))
    if column.startswith("error_"):
        return label(f"error of {column[len('error_'):]} (eq. 52)", "")
    if column in _COUNTS:
        return _COUNTS[column]
    for suffix in ("_final", "_min", "_max"):
        if column.endswith(suffix):
            name = column[: -len(suffix)]
            return label(f"{name} ({suffix[1:]})", observable_unit(scene, name))
    return label(column, parameter_unit(scene, column))


def sweep_groups(rows_values: dict[str, np.ndarray], x: str) -> tuple[list[str], list[tuple]]:
    """The swept names other than ``x`` and their distinct value combinations
    (sorted): the members of one group differ only in ``x``."""
    others = [k for k in rows_values if k != x]
    n = len(next(iter(rows_values.values())))
    keys = sorted(set(zip(*(rows_values[k] for k in others)))) if others else [()]
    return others, keys if n else []


def sweep_axis(rows_values: dict[str, np.ndarray]) -> str:
    """The x axis of a sweep plot: the first swept value that varies, unless
    that leaves more than :data:`MAX_LINES` groups and another leaves fewer."""
    varying = [k for k, v in rows_values.items() if np.unique(v).size > 1] or list(rows_values)[:1]
    x = varying[0]
    if len(sweep_groups(rows_values, x)[1]) > MAX_LINES:
        x = min(varying, key=lambda k: len(sweep_groups(rows_values, k)[1]))
    return x


def _number(value) -> float:
    """A table cell as a float: a missing or empty cell (eq. 52 undefined for a
    member whose reference is identically zero) is left out of the plot."""
    return np.nan if value is None or value == "" else float(value)


def _value_text(scene, name: str, value: float) -> str:
    """``"h = 0.001 s"``, ``"e = 0.5"``: a swept value with its unit."""
    unit = parameter_unit(scene, name)
    return f"{name} = {value:g}" + (f" {unit}" if unit else "")


def _group_style(j: int) -> dict:
    """The j-th line of a sweep panel: its own hollow marker, smaller for
    each line, and line style, so that lines lying on each other stay visible."""
    return dict(marker="osD^v<>p"[j % 8], markersize=max(3.0, 7.5 - 0.7 * j), markerfacecolor="none",
                linestyle=("-", "--", ":", "-.")[j % 4], alpha=0.9)


def sweep_figure(result, columns: Sequence[str], scene=None, scheme: str = ""):
    """Sweep columns against one swept value (:func:`sweep_axis`), one line
    per combination of the other swept values, step sizes included
    (:func:`sweep_groups`): members that differ in another swept value are
    never joined. With more than :data:`MAX_LINES` combinations the members
    are markers only. Failed runs are red crosses; one legend for the figure."""
    values = {k: result.column(k).astype(float) for k in result.swept}
    x_name = sweep_axis(values)
    others, keys = sweep_groups(values, x_name)
    joined = len(keys) <= MAX_LINES
    x = values[x_name]
    failed = np.asarray([bool(r.get("failed_steps")) for r in result.rows])
    spec = scene_spec(scene)
    ncol = min(3, len(columns))
    nrow = -(-len(columns) // ncol)
    log_x = x_name == "h" or bool(np.all(x > 0) and x.max() >= 50 * x.min())
    with style():
        fig, axes = figure(nrow, ncol, panel=(3.9, 2.9))
        for ax, col in zip(axes.flat, columns):
            y = np.asarray([_number(r.get(col)) for r in result.rows], dtype=float)
            if joined:
                for j, key in enumerate(keys):
                    sel = np.ones(x.size, bool)
                    for k, v in zip(others, key):
                        sel &= values[k] == v
                    order = np.argsort(x[sel], kind="stable")
                    text = ", ".join(_value_text(spec, k, v) for k, v in zip(others, key))
                    ax.plot(x[sel][order], y[sel][order], label=text or "_run", gid="group", **_group_style(j))
            else:
                spread = [k for k in others if np.unique(values[k]).size > 1]
                ax.plot(x, y, "o", ms=3, alpha=0.6, label=f"{len(keys)} combinations of {', '.join(spread)}",
                        gid="group")
            bad = failed & np.isfinite(y)
            if bad.any():
                ax.plot(x[bad], y[bad], "x", color="r", ms=8, mew=1.6, label="failed run", gid="failed")
            finite = y[np.isfinite(y)]
            if col.startswith("error_") and finite.size and np.all(finite > 0):
                ax.set_yscale("log")
                log_ticks(ax, "y")
            if log_x:
                ax.set_xscale("log")
                log_ticks(ax, "x", np.unique(x))
            ax.set_xlabel(label(x_name, parameter_unit(spec, x_name)))
            ax.set_ylabel(column_label(col, spec))
        hide_unused(axes, len(columns))
        figure_legend(fig, axes.flat[: len(columns)])
        varying = [k for k, v in values.items() if np.unique(v).size > 1]
        what = f"sweep over {', '.join(varying) or x_name} ({len(result.rows)} runs"
        what += ")" if joined else f"; markers only: {len(keys)} combinations)"
        name = spec.name if spec is not None else str(scene or "")
        fig.suptitle(title(name, scheme, values.get("h", ()), what))
    return fig


__all__ = ["MAX_LINES", "column_label", "sweep_axis", "sweep_figure", "sweep_groups"]
