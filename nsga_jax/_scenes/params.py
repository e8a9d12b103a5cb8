"""Typed, range-checked scene parameters and solver settings.

Every numeric field of a scene config has a :class:`Param` that states its
unit, default and allowed range; values are checked before anything is traced,
and an error names the field and the range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from .._results import ConfigError
from .._validation import (
    ENERGETIC_SCHEMES,
    IMPACT_LAWS,
    IMPACT_TIMINGS,
    SCHEME_NAMES,
    WARM_WITH_PERSISTENT,
    Range,
    time_grid,
)


@dataclass(frozen=True)
class Param:
    """One config field.

    ``kind`` is ``"float"``, ``"int"`` or ``"choice"``; ``lo``/``hi`` bound
    float and int fields (``lo_open``/``hi_open`` exclude the bound);
    ``choices`` lists the values of a choice field.
    """

    default: Any
    doc: str
    unit: str = ""
    kind: str = "float"
    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] = ()
    note: str = ""

    @property
    def range(self) -> Range:
        """The allowed interval of a float or int field."""
        return Range(self.lo, self.hi, self.lo_open, self.hi_open)

    def range_text(self) -> str:
        if self.kind == "choice":
            return "one of " + ", ".join(repr(c) for c in self.choices)
        return self.range.text()

    def check(self, name: str, value: Any) -> Any:
        """Return the value converted to its kind, or raise :class:`ConfigError`."""
        unit = f" [{self.unit}]" if self.unit else ""
        if self.kind == "choice":
            if value not in self.choices:
                raise ConfigError(f"{name} must be {self.range_text()}, got {value!r}")
            return value
        if isinstance(value, bool):
            raise ConfigError(f"{name}{unit} must be a number, got {value!r}")
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ConfigError(f"{name}{unit} must be a number, got {value!r}") from None
        if not math.isfinite(x):
            raise ConfigError(f"{name}{unit} must be finite (in {self.range_text()}), got {value!r}")
        if self.kind == "int":
            if x != int(x):
                raise ConfigError(f"{name} must be an integer in {self.range_text()}, got {value!r}")
            x = int(x)
        if not self.range.contains(x):
            note = f" ({self.note})" if self.note else ""
            raise ConfigError(f"{name}{unit} must be in {self.range_text()}{note}, got {value!r}")
        return x


def positive(default, doc, unit="") -> Param:
    return Param(default, doc, unit, lo=0.0, lo_open=True)


def nonnegative(default, doc, unit="") -> Param:
    return Param(default, doc, unit, lo=0.0)


def unit_interval(default, doc) -> Param:
    return Param(default, doc, "", lo=0.0, hi=1.0)


def friction_coefficient(default: float = 0.0, where: str = "at every contact point") -> Param:
    """The Coulomb coefficient ``mu`` (>= 0) of a scene's contacts; 0 (the
    default of the scenes that had no friction) builds frictionless contacts
    (``mu=None``), so their runs are those without friction."""
    return Param(default, f"Coulomb friction coefficient {where} (0: frictionless contacts)", lo=0.0,
                 note="a friction coefficient is >= 0")


def contact_mu(p, concrete):
    """A contact's ``mu`` argument: the traced ``p["mu"]`` where the validated
    ``concrete["mu"]`` is > 0 (the contact carries friction rows), else ``None``."""
    return p["mu"] if concrete["mu"] > 0 else None


SOLVER_PARAMS: dict[str, Param] = {
    "scheme": Param("ds", "time integration scheme: decoupled (ds), decoupled without f^p and f* (dsn), "
                    "coupled (cs), Moreau-Jean (mj)", kind="choice", choices=SCHEME_NAMES),
    "h": positive(1e-3, "step size", "s"),
    "t_end": positive(1.0, "end time (the run starts at t = 0)", "s"),
    "rho_inf": unit_interval(0.8, "spectral radius at infinity ρ∞ of generalized-α (eq. 35)"),
    "theta": unit_interval(0.5, "θ of the Moreau-Jean scheme (mj only)"),
    "tol_r": Param(1e-5, "relative Newton tolerance of eq. 51", lo=0.0, lo_open=True, hi=1.0, hi_open=True),
    "tol_f": positive(1e-5, "reference Newton tolerance of eq. 51"),
    "max_iter": Param(50, "Newton iteration cap per sub-problem", kind="int", lo=1, hi=10_000),
    "dtype": Param("float64", "floating-point precision of the run", kind="choice", choices=("float64", "float32")),
    "impact_law": Param("newton", "impact law with restitution: Newton's (newton) or, with friction, one that "
                        "cannot create energy (energetic; ds and dsn only; see docs/friction.md)", kind="choice",
                        choices=IMPACT_LAWS),
    "impacts": Param("end", "where an impact is applied: at the end of the step that holds it, as in the paper "
                     "(end), or at its instant inside the step (instants; ds and dsn only; see docs/scheme.md)",
                     kind="choice", choices=IMPACT_TIMINGS),
    "newton_start": Param("zero", "Newton's start of each step's position correction and velocity jump: zero "
                          "multipliers, as in the paper (zero), or the last step's (previous: resting contacts "
                          "converge in fewer iterations; ds and dsn only; see docs/friction.md)", kind="choice",
                          choices=("zero", "previous")),
    "persistent_contacts": Param("jumps", "where the force of a contact that stays closed from step to step is "
                                 "integrated: in the position correction and the velocity jump, at first order, as "
                                 "in the paper (jumps), or in the smooth motion, at second order (smooth: resting, "
                                 "sliding and rocking bodies keep their energy; ds and dsn only; see "
                                 "docs/friction.md)", kind="choice", choices=("jumps", "smooth")),
    "record_every": Param(1, "keep every k-th step (and the last) in memory, on disk and in trajectory.npz; "
                          "the statistics cover every step", kind="int", lo=1,
                          hi=1_000_000_000),
}


def check_solver(solver: dict[str, Any]) -> None:
    """Cross-field rules of validated solver settings: h in (0, t_end], a step
    that advances time in the run's precision, a step count that fits, an
    energetic impact law only with a scheme that carries it."""
    time_grid(0.0, solver["t_end"], solver["h"], solver["dtype"], t1_name="t_end")
    law = solver.get("impact_law", "newton")
    if law != "newton" and solver["scheme"] not in ENERGETIC_SCHEMES:
        raise ConfigError(f"impact_law = {law!r} is carried by the schemes {', '.join(ENERGETIC_SCHEMES)}; "
                          f"scheme = {solver['scheme']!r} imposes Newton's law (impact_law = 'newton')")
    if solver.get("newton_start", "zero") != "zero" and solver["scheme"] not in ENERGETIC_SCHEMES:
        raise ConfigError(f"newton_start = {solver['newton_start']!r} is an option of the schemes "
                          f"{', '.join(ENERGETIC_SCHEMES)}; scheme = {solver['scheme']!r} starts Newton at zero "
                          "(newton_start = 'zero')")
    if solver.get("persistent_contacts", "jumps") != "jumps" and solver["scheme"] not in ENERGETIC_SCHEMES:
        raise ConfigError(f"persistent_contacts = {solver['persistent_contacts']!r} is an option of the schemes "
                          f"{', '.join(ENERGETIC_SCHEMES)}; scheme = {solver['scheme']!r} integrates contact forces "
                          "in its jumps (persistent_contacts = 'jumps')")
    if solver.get("persistent_contacts", "jumps") != "jumps" and solver.get("newton_start", "zero") != "zero":
        raise ConfigError(WARM_WITH_PERSISTENT)
    if solver.get("impacts", "end") != "end" and solver["scheme"] not in ENERGETIC_SCHEMES:
        raise ConfigError(f"impacts = {solver['impacts']!r} is an option of the schemes "
                          f"{', '.join(ENERGETIC_SCHEMES)}; scheme = {solver['scheme']!r} applies impacts at the end "
                          "of the step (impacts = 'end')")


def check_all(section: str, specs: dict[str, Param], values: dict[str, Any]) -> dict[str, Any]:
    """Check ``values`` against ``specs``; unknown keys are refused. Missing keys take defaults."""
    unknown = sorted(set(values) - set(specs))
    if unknown:
        raise ConfigError(
            f"unknown {section} key {unknown[0]!r}; allowed keys: {', '.join(sorted(specs))}"
        )
    out = {}
    for name, spec in specs.items():
        out[name] = spec.check(name, values[name]) if name in values else spec.default
    return out
