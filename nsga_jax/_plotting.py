"""Figures: one style, units, titles and axis helpers for every PNG nsga_jax writes.

Figures are :class:`matplotlib.figure.Figure` objects drawn by the Agg canvas,
never through ``pyplot``: plotting needs no display and never changes the
user's matplotlib backend, and importing nsga_jax does not import matplotlib
at all (each function here imports it when called). Every PNG goes through
:func:`save`; :func:`capture` collects the figures saved while it is active,
so a caller (a test, a notebook) can inspect what was written::

    with nsga_jax._plotting.capture() as figures:
        nsga_jax._output.write_run(sol, "out", info)
    figures[Path("out/observables.png")].axes

Axis labels read ``quantity [unit]`` (``[-]`` for a dimensionless quantity);
counts (iterations, linear solves) are labelled by what they count. Units come
from the scene: :attr:`SceneSpec.units <nsga_jax.scenes.SceneSpec.units>`
for observables, the :class:`~nsga_jax._scenes.params.Param` units for
parameters.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._results import SUBPROBLEM_LABELS

if TYPE_CHECKING:
    from matplotlib.typing import RcKeyType

STYLE: dict[RcKeyType, Any] = {
    "font.size": 9.0,
    "axes.titlesize": 9.0,
    "axes.labelsize": 9.0,
    "figure.titlesize": 10.0,
    "legend.fontsize": 8.0,
    "xtick.labelsize": 8.0,
    "ytick.labelsize": 8.0,
    "axes.grid": True,
    "axes.grid.which": "both",
    "grid.alpha": 0.3,
    "grid.linewidth": 0.6,
    "lines.linewidth": 1.2,
    "axes.formatter.useoffset": False,  # an offset ("+1e3") hides the values read off an axis
    "axes.formatter.limits": (-3, 4),
    "legend.framealpha": 0.85,
}
"""rcParams of every figure (a :func:`matplotlib.rc_context`, never set globally)."""

DPI = 120

SCHEME_STYLE = {
    "ds": dict(marker="o", linestyle="-", markersize=8.5, markerfacecolor="none", markeredgewidth=1.4,
               alpha=0.9, zorder=2),
    "dsn": dict(marker="s", linestyle="--", markersize=6.5, markerfacecolor="none", markeredgewidth=1.2,
                alpha=0.9, zorder=3),
    "cs": dict(marker="^", linestyle=":", markersize=5.0, linewidth=1.6, alpha=0.85, zorder=4),
    "mj": dict(marker="D", linestyle="-.", markersize=3.5, alpha=0.85, zorder=5),
}
"""Per scheme a marker, a line style and a marker size (largest and hollow
first), so that identical curves of several schemes stay visible."""

SUBPROBLEMS = ("smooth motion", "position correction", "velocity jump")
"""The three sub-problems of a DS step, in the order of its ``Solution.iterations``."""


def subproblem_labels(names, count: int) -> tuple[str, ...]:
    """What plots call a scheme's sub-problems (``Solution.subproblems``); without
    names, DS's three (or ``sub-problem i``) for ``count`` columns."""
    if names:
        return tuple(SUBPROBLEM_LABELS.get(n, n) for n in names)
    return SUBPROBLEMS if count == len(SUBPROBLEMS) else tuple(f"sub-problem {i + 1}" for i in range(count))


# ------------------------------------------------------------ figures, saving


@contextmanager
def style() -> Iterator[None]:
    """The package's plot style, for building and saving a figure."""
    import matplotlib

    with matplotlib.rc_context(STYLE):
        yield


def figure(nrows: int = 1, ncols: int = 1, *, panel: tuple[float, float] = (4.2, 2.8), **subplots):
    """A constrained-layout figure of ``nrows x ncols`` panels, each ``panel``
    inches; returns ``(fig, axes)`` with ``axes`` a 2-D array."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(panel[0] * ncols, panel[1] * nrows + 0.5), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **subplots)
    return fig, axes


_captures: list[dict[Path, Any]] = []


def save(fig, path: str | Path) -> Path:
    """Draw ``fig`` with the Agg canvas into the PNG ``path``; returns the path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    path = Path(path)
    FigureCanvasAgg(fig)
    with style():
        fig.savefig(path, dpi=DPI)
    for figures in _captures:
        figures[path] = fig
    return path


@contextmanager
def capture() -> Iterator[dict[Path, Any]]:
    """Collect ``{path: Figure}`` of every figure :func:`save` writes meanwhile."""
    figures: dict[Path, Any] = {}
    _captures.append(figures)
    try:
        yield figures
    finally:
        _captures.remove(figures)


# ---------------------------------------------------------------- units, text


def scene_spec(scene):
    """The :class:`~nsga_jax.scenes.SceneSpec` of a scene name, a
    :class:`~nsga_jax.scenes.Scene` or a spec; ``None`` if unknown."""
    from ._scenes import REGISTRY

    if scene is None or scene == "":
        return None
    if isinstance(scene, (str, Path)):
        return REGISTRY.get(str(scene))
    return getattr(scene, "spec", scene)


def _agreed(values: set[str]) -> str | None:
    return values.pop() if len(values) == 1 else None


def observable_unit(scene, name: str) -> str | None:
    """The unit of observable ``name`` of ``scene`` (``""``: dimensionless);
    without a known scene, the unit every built-in scene agrees on, else ``None``."""
    from ._scenes import REGISTRY

    spec = scene_spec(scene)
    if spec is not None and name in spec.units:
        return spec.units[name]
    return _agreed({s.units[name] for s in REGISTRY.values() if name in s.units})


def parameter_unit(scene, name: str) -> str | None:
    """The unit of a swept value: ``"s"`` for ``h``, else the scene parameter's
    (or the one every built-in scene agrees on); ``None`` if unknown."""
    from ._scenes import REGISTRY

    if name == "h":
        return "s"
    spec = scene_spec(scene)
    if spec is not None and name in spec.parameters:
        return spec.parameters[name].unit
    return _agreed({s.parameters[name].unit for s in REGISTRY.values() if name in s.parameters})


def unit_text(unit: str | None) -> str:
    """``"m/s^2"`` -> ``"[m/s$^{2}$]"``; ``""`` -> ``"[-]"``; ``None`` -> ``""``."""
    if unit is None:
        return ""
    if unit == "":
        return "[-]"
    return "[" + re.sub(r"\^(-?\d+)", r"$^{\1}$", unit) + "]"


def label(quantity: str, unit: str | None) -> str:
    """An axis label ``quantity [unit]``."""
    text = unit_text(unit)
    return f"{quantity} {text}" if text else quantity


def h_text(hs: Sequence[float]) -> str:
    """``"h = 0.001 s"`` or, for several step sizes, ``"h = 0.0005 ... 0.002 s"``."""
    hs = sorted({float(h) for h in hs})
    if not hs:
        return ""
    if len(hs) == 1:
        return f"h = {hs[0]:g} s"
    return f"h = {hs[0]:g} ... {hs[-1]:g} s ({len(hs)} values)"


def title(scene: str = "", schemes: Sequence[str] | str = (), hs: Sequence[float] | float = (),
          what: str = "") -> str:
    """A figure title ``scene · SCHEMES · h = ... s``, then ``what`` on a second line."""
    if isinstance(schemes, str):
        schemes = [schemes] if schemes else []
    if isinstance(hs, (int, float)):
        hs = [hs]
    head = " · ".join(p for p in (str(scene or ""), ", ".join(s.upper() for s in dict.fromkeys(schemes)),
                                  h_text(hs)) if p)
    return "\n".join(p for p in (head, what) if p)


def scheme_style(scheme: str, index: int = 0) -> dict:
    """Line and marker keywords of a scheme (:data:`SCHEME_STYLE`); another
    name gets a marker by its position."""
    if scheme in SCHEME_STYLE:
        return dict(SCHEME_STYLE[scheme])
    return dict(marker="v<>pHX*"[index % 7], linestyle="-", markersize=5.0, alpha=0.85)


# --------------------------------------------------------------------- axes


def integer_ticks(ax, axis: str = "y", top: float | None = None) -> None:
    """Ticks at integers only (iteration counts): every integer up to a
    ``top`` of at most 6, else a few."""
    from matplotlib.ticker import MaxNLocator, MultipleLocator

    locator = (MultipleLocator(1) if top is not None and top <= 6 else
               MaxNLocator(integer=True, steps=[1, 2, 5, 10], min_n_ticks=2))
    getattr(ax, f"{axis}axis").set_major_locator(locator)


def log_ticks(ax, axis: str = "x", values: Sequence[float] | np.ndarray | None = None, max_ticks: int = 6) -> None:
    """Readable ticks on a log axis: at ``values`` (e.g. the step sizes of a
    study) when they are few and far enough apart, else at 1, 2, 5 or 1 per
    decade as the span allows; plain ``%g`` labels and no minor labels, so
    that labels never collide."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter

    which = getattr(ax, f"{axis}axis")
    fmt = FuncFormatter(lambda v, _: f"{v:g}")
    which.set_minor_formatter(NullFormatter())
    if values is not None:
        v = np.unique([x for x in np.asarray(values, float).ravel() if np.isfinite(x) and x > 0])
        if 1 <= v.size <= max_ticks and (v.size == 1 or np.min(np.diff(np.log10(v))) >= 0.12):
            # matplotlib's stub asks for a Sequence[float]; FixedLocator takes any array (np.asarray)
            which.set_major_locator(FixedLocator(v))  # type: ignore[arg-type]
            which.set_major_formatter(fmt)
            return
    lo, hi = (ax.get_xlim() if axis == "x" else ax.get_ylim())
    span = math.log10(max(hi, 1e-300) / max(lo, 1e-300)) if lo > 0 and hi > 0 else 10.0
    subs = (1.0, 2.0, 5.0) if span <= 1.6 else (1.0, 3.0) if span <= 2.5 else (1.0,)
    which.set_major_locator(LogLocator(base=10.0, subs=subs, numticks=max_ticks + 1))
    which.set_major_formatter(fmt if span <= 4 else which.get_major_formatter())


def plain_ticks(ax, axis: str = "x", nbins: int = 6) -> None:
    """At most ``nbins`` ticks on a linear axis at round values, labelled in
    ``%g`` (``0.005``, not ``0.0050``), so that labels never collide."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    which = getattr(ax, f"{axis}axis")

    def fmt(v, _):
        lo, hi = which.get_view_interval()
        return f"{0.0 if abs(v) < 1e-9 * abs(hi - lo) else v:.6g}"

    which.set_major_locator(MaxNLocator(nbins=nbins, steps=[1, 2, 2.5, 5, 10]))
    which.set_major_formatter(FuncFormatter(fmt))


def flat_limits(ax, y) -> None:
    """A quantity constant to plotting precision (changes below 1e-6 of its
    size, e.g. a conserved energy) is drawn flat on a 1 % wide axis rather
    than on an axis that magnifies round-off."""
    y = np.asarray(y, float)
    y = y[np.isfinite(y)]
    if y.size == 0:
        return
    size = float(np.max(np.abs(y)))
    if 0.0 < np.ptp(y) <= 1e-6 * size:
        mid = 0.5 * (float(y.max()) + float(y.min()))
        ax.set_ylim(mid - 0.005 * size, mid + 0.005 * size)


def bottom_labels(axes, text: str) -> None:
    """``text`` as the x label of the lowest visible panel of each column,
    with tick labels there (shared x axes hide them elsewhere)."""
    nrows, ncols = axes.shape
    for j in range(ncols):
        visible = [i for i in range(nrows) if axes[i, j].get_visible()]
        if visible:
            ax = axes[visible[-1], j]
            ax.set_xlabel(text)
            ax.tick_params(labelbottom=True)


def figure_legend(fig, axes):
    """One legend for the figure, right of the panels (never over data): the
    labelled lines of every panel, each label once. ``None`` if none."""
    handles: dict[str, Any] = {}
    for ax in np.ravel(axes):
        for handle, text in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(text, handle)
    if not handles:
        return None
    return fig.legend(list(handles.values()), list(handles), loc="outside right upper")


def hide_unused(axes, used: int) -> None:
    """Hide the panels after the first ``used``."""
    for ax in list(axes.flat)[used:]:
        ax.set_visible(False)


# ------------------------------------------------------------------ sweeps


__all__ = ["STYLE", "SCHEME_STYLE", "SUBPROBLEMS", "subproblem_labels", "style", "figure", "save", "capture",
           "scene_spec",
           "observable_unit", "parameter_unit", "unit_text", "label", "h_text", "title", "scheme_style",
           "integer_ticks", "log_ticks", "plain_ticks", "flat_limits", "bottom_labels", "figure_legend",
           "hide_unused"]
