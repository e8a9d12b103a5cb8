"""One validation vocabulary for every entry point: the command line, config
files, model constructors, :func:`~nsga_jax.simulate`, batches, sweeps and
identification.

Every check runs on concrete Python or NumPy values before anything is traced
or compiled. A wrong Python type (a scheme class where an instance belongs, a
string where a model belongs) raises :class:`TypeError`; a value of the right
kind that the physics or the machine cannot take raises
:class:`~nsga_jax.ConfigError`. Either message names the argument, the value
and what is allowed.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from ._results import ConfigError

MAX_STEPS = 2**62
"""The most steps a run may take: step counts are Python integers on the host
and the compiled loops count only within a chunk, so no counter overflows;
this bound only keeps ``t0 + n h`` meaningful."""

TIME_RESOLUTION = 2.0
"""A step must be at least this many units in the last place of the run's
latest time in its precision: below that, ``t + h`` rounds back to ``t`` (or
to a visibly wrong time) and the run would never advance."""

def describe(value: Any) -> str:
    """A short description of a value for an error message."""
    if isinstance(value, type):
        return f"the class {value.__name__} (an instance is needed: {value.__name__}())"
    text = repr(value)
    if len(text) > 80:
        text = text[:77] + "..."
    return f"{type(value).__name__} {text}"


def require_instance(name: str, value: Any, kind: type | tuple[type, ...], expected: str) -> None:
    """Raise :class:`TypeError` unless ``value`` is an instance of ``kind``."""
    if not isinstance(value, kind):
        raise TypeError(f"{name} must be {expected}, got {describe(value)}")


def interval_text(lo: float, hi: float, lo_open: bool, hi_open: bool) -> str:
    left = "(" if lo_open or lo == -math.inf else "["
    right = ")" if hi_open or hi == math.inf else "]"
    low = "-inf" if lo == -math.inf else f"{lo:g}"
    high = "inf" if hi == math.inf else f"{hi:g}"
    return f"{left}{low}, {high}{right}"


SCHEME_NAMES = ("ds", "dsn", "cs", "mj")
"""The schemes' names in configs, on the command line and in ``nsga_jax.SCHEMES``
(:func:`nsga_jax._integrators.scheme_class` gives each class)."""

IMPACT_LAWS = ("newton", "energetic")
"""The values of DS's and DSn's ``impact_law`` (the solver key ``impact_law``,
``--impact-law``): Newton's restitution, or the energetic law that cannot
create energy with friction (:mod:`nsga_jax._integrators.impact_law`)."""
ENERGETIC_SCHEMES = ("ds", "dsn")
"""The schemes that carry the energetic impact law; CS and MJ impose Newton's."""

IMPACT_TIMINGS = ("end", "instants")
"""Where DS and DSn apply an impact (the solver key ``impacts``,
``--impacts``): at the end of the step that holds it, as in the paper, or at
its instant inside the step (``DS(impact_instants=True)``,
:mod:`nsga_jax._integrators.impact_instants`)."""

class Range(NamedTuple):
    """A field's allowed interval; ``lo_open``/``hi_open`` exclude the bound.
    The declarative form of :func:`real`'s bounds, for model fields
    (``Model.ranges``) and scene parameters."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False

    def contains(self, x) -> bool:
        x = np.asarray(x)
        above = x > self.lo if self.lo_open else x >= self.lo
        below = x < self.hi if self.hi_open else x <= self.hi
        return bool(np.all(above & below))

    def text(self) -> str:
        return interval_text(self.lo, self.hi, self.lo_open, self.hi_open)


POSITIVE = Range(0.0, math.inf, lo_open=True)
UNIT_INTERVAL = Range(0.0, 1.0)


def real(name: str, value: Any, lo: float = -math.inf, hi: float = math.inf, *, lo_open: bool = False,
         hi_open: bool = False, unit: str = "", note: str = "") -> float:
    """``value`` as a finite float in the interval, else :class:`ConfigError`
    (booleans and strings are not numbers here)."""
    label = f"{name} [{unit}]" if unit else name
    allowed = interval_text(lo, hi, lo_open, hi_open)
    if isinstance(value, (bool, np.bool_, str, bytes)) or value is None:
        raise ConfigError(f"{label} must be a real number in {allowed}, got {describe(value)}")
    try:
        if np.ndim(value) != 0:
            raise TypeError
        x = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{label} must be a real number in {allowed}, got {describe(value)}") from None
    if not math.isfinite(x):
        raise ConfigError(f"{label} must be finite (in {allowed}), got {value!r}")
    if x < lo or x > hi or (lo_open and x == lo) or (hi_open and x == hi):
        extra = f" ({note})" if note else ""
        raise ConfigError(f"{label} must be in {allowed}{extra}, got {value!r}")
    return x


def integer(name: str, value: Any, lo: int = 1, hi: int | None = None) -> int:
    """``value`` as a Python int in [lo, hi], else :class:`ConfigError`
    (floats with a fractional part, booleans and strings are refused)."""
    allowed = f"an integer >= {lo}" + ("" if hi is None else f" and <= {hi}")
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if not ok:  # name the type: True, 2.5 and "3" all look like counts
        raise ConfigError(f"{name} must be {allowed}, got {describe(value)}")
    if value < lo or (hi is not None and value > hi):
        raise ConfigError(f"{name} must be {allowed}, got {value!r}")
    return int(value)


def choice(name: str, value: Any, choices: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise ConfigError(f"{name} must be one of {', '.join(map(repr, choices))}, got {value!r}")
    return value


def step_count(t0: float, t1: float, h: float) -> int:
    """N = floor((t1 - t0) / h) steps (at least one), with a relative slack
    of 1e-9 so that an h that divides the interval gives its exact count."""
    n = (t1 - t0) / h
    return max(1, int(math.floor(n + 1e-9)))


def time_grid(t0: Any, t1: Any, h: Any, dtype: str = "float64", *, t1_name: str = "t1") -> tuple[float, float,
                                                                                              float, int]:
    """Check a run's times and return ``(t0, t1, h, n_steps)``.

    Rules: finite numbers, ``t1 > t0``, ``h`` in (0, t1 - t0], ``t + h > t``
    at the latest time in the run's precision (with a margin of
    :data:`TIME_RESOLUTION` units in the last place), at most
    :data:`MAX_STEPS` steps.
    """
    t0 = real("t0", t0)
    t1 = real(t1_name, t1)
    h = real("h", h, 0.0, lo_open=True)
    if t1 <= t0:
        raise ConfigError(f"{t1_name} must be finite and greater than t0, got t0={t0}, {t1_name}={t1}")
    if h > t1 - t0:
        span = t1_name if t1_name == "t_end" else f"{t1_name} - t0"
        raise ConfigError(f"h must be in (0, {span}] = (0, {t1 - t0:g}], got {h}")
    latest = max(abs(t0), abs(t1))
    resolution = TIME_RESOLUTION * float(np.spacing(np.asarray(latest, dtype=dtype)))
    if h < resolution:
        raise ConfigError(f"h = {h:g} s is below the time resolution of {dtype} at t = {latest:g} s "
                          f"(t + h would round to t): h must be >= {resolution:.3g} s in {dtype}")
    n_steps = step_count(t0, t1, h)
    if n_steps > MAX_STEPS:
        raise ConfigError(f"the run has {n_steps:.3g} steps ((t1 - t0)/h); at most {MAX_STEPS:.3g} are allowed")
    return t0, t1, h, n_steps


WARM_WITH_PERSISTENT = (  # refused by run_inputs.check_scheme and the scenes' check_solver
    "warm_start=True (newton_start = 'previous') is refused with persistent_contacts=True (persistent_contacts = "
    "'smooth'): the smooth motion then carries the resting contacts, the position correction and velocity jump "
    "take 0 or 1 iteration a step without a warm start, and the multipliers a held contact hands on (the drift "
    "of the smooth motion's rows) are no start for a landing (the rocking block failed a step at h = 2e-3 s); "
    "choose one")


__all__ = ["ENERGETIC_SCHEMES", "IMPACT_LAWS", "MAX_STEPS", "POSITIVE", "SCHEME_NAMES", "UNIT_INTERVAL", "Range",
           "WARM_WITH_PERSISTENT",
           "check_model_fields", "choice", "describe", "integer", "interval_text", "real", "refuse_traced",
           "require_instance", "step_count", "time_grid"]


# ----------------------------------------------------------- models, schemes


def _concrete_leaves(tree):
    """(path, leaf) of every floating-point leaf that holds concrete values."""
    import equinox as eqx
    import jax

    return [(p, x) for p, x in jax.tree_util.tree_leaves_with_path(tree)
            if eqx.is_inexact_array(x) and not isinstance(x, jax.core.Tracer)]


def refuse_traced(driver: str, **inputs: Any) -> None:
    """Raise :class:`TypeError` when a host driver (``simulate``, a batch) is
    called under a JAX transformation (``jax.grad``, ``jit``, ``vmap``): its
    loop runs on the host, chunk by chunk, and cannot be traced; the pure
    :func:`~nsga_jax.integrate` takes the same arguments and is."""
    import jax

    for name, value in inputs.items():
        if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(value)):
            raise TypeError(f"{driver} is a host driver and cannot be differentiated, jitted or vmapped ({name} "
                            f"is traced); nsga_jax.integrate takes the same arguments and is one pure JAX "
                            f"function for jax.grad, jit and vmap (docs/gradients.md)")


def check_model_fields(model) -> None:
    """Every float field finite, each named field in its ``ranges``, and the
    model's own rules (``invalid()``), on concrete values (traced fields are
    checked where they were made)."""
    import jax

    cls = type(model).__name__
    for path, leaf in _concrete_leaves(model):
        values = np.asarray(leaf)
        if not np.all(np.isfinite(values)):
            raise ConfigError(f"{cls}{jax.tree_util.keystr(path)} must be finite, got {values.tolist()}")
    for name, rng in model.ranges.items():
        value = getattr(model, name)
        if value is None or isinstance(value, jax.core.Tracer):  # None: an optional field left out
            continue
        value = np.asarray(value)
        if not rng.contains(value):
            raise ConfigError(f"{cls}.{name} must be in {rng.text()}, got {value.tolist()}")
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(model))
    message = None if traced else model.invalid()
    if message:
        raise ConfigError(f"{cls}.{message}")
