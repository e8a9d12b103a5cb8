"""Invariant monitors: what every run reports beyond its trajectory.

:class:`RunTotals` adds up, chunk by chunk on the host, statistics over every
step of a run (also those a strided record leaves out): Newton iterations per
sub-problem (named as the scheme names them), failed steps, the largest penetration and bilateral violations,
and, for a model with an ``energy(q, v)``, the energy at the start and the
end, the largest rise over one step and the largest rise over one step with a
contact impulse (an *impact step*). :func:`invariant_warnings` compares them
with :class:`Tolerances` and names each one exceeded; energy created at an
impact (the scheme's law with e ≤ 1 never creates it) is the warning that
``strict`` runs turn into a failure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ._results import Result

CHAIN_WARNING = "impacts in sequence within one step"
"""The start of the warning for a step in which one impact closed another
contact (the step resolves them simultaneously)."""

ENERGY_WARNING = "energy rise at an impact"
"""The start of the warning :func:`invariant_warnings` gives for energy
created at an impact step (what ``strict`` turns into a failure)."""

CHAIN_REACH = 2.0
"""The most an impact's neighbour can travel in a step, in units of the
impact's own approach over the step: an impact with e <= 1 gives a body at
most twice the speed that struck it."""
SIMULTANEOUS = 1e-3
"""An open contact whose gap at the step's start is below this fraction of
the impact's approach over the step closes within that fraction of the step
after it: the two impacts are simultaneous at the step's resolution (a
resting corner the position correction left open by 1e-11 m, within its
tolerance, as the rocking block lands on its other corner)."""
ENERGETIC_HINT = ('the impact law impact_law = "energetic" (DS, DSn; Python: DS(impact_law="energetic"), '
                  'a config\'s [solver] impact_law, or --impact-law energetic) cannot create energy')
"""What the energy warning offers where friction and e > 0 can cause the rise."""


@dataclass(frozen=True)
class Tolerances:
    """Bounds past which a run's summary warns.

    Attributes:
        penetration: largest allowed penetration of a unilateral gap [m].
        bilateral: largest allowed bilateral violation |g^B| [m].
        bilateral_rate: largest allowed velocity-level violation |g_q^B v| [m/s].
        impact_energy: largest allowed energy rise over an impact step, as a
            fraction of the run's energy scale (the largest |E| or kinetic
            energy seen).
        rotation_per_step: largest rotation of a body over one step [rad]
            before a run warns that the step is coarse for the motion.
    """

    penetration: float = 1e-6
    bilateral: float = 1e-6
    bilateral_rate: float = 1e-4
    impact_energy: float = 1e-2
    rotation_per_step: float = 0.2


def default_tolerances(dtype: str = "float64") -> Tolerances:
    """The default bounds; a float32 run's constraint bounds are 100 times
    looser (its round-off is 2**29 times a float64 run's)."""
    if dtype == "float32":
        return Tolerances(penetration=1e-4, bilateral=1e-4, bilateral_rate=1e-2)
    return Tolerances()


@dataclass
class RunTotals:
    """Statistics over every step of a run, added chunk by chunk, so that they
    cover the steps a strided record leaves out: Newton iterations (sum and max
    per sub-problem, in the order of ``subproblems``, the scheme's names, taken
    from the first records added; and of their total, the linear solves per step), failed
    step numbers and the first one's result code, the smallest gap [m], the
    largest bilateral violations (position [m], velocity [m/s]) and the
    energy monitors [J] (when energies are given)."""

    n_bilateral: int = 0
    n_steps: int = 0
    subproblems: tuple[str, ...] = ()
    iterations_sum: np.ndarray = field(default_factory=lambda: np.zeros(0))
    iterations_max: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    solves_sum: float = 0.0
    solves_max: int = 0
    failed: list[int] = field(default_factory=list)
    first_result: int = 0
    instants: int = 0
    fallbacks: int = 0
    min_gap: float = math.inf
    max_bilateral: float = 0.0
    max_bilateral_rate: float = 0.0
    energy_initial: float = math.nan
    energy_last: float = math.nan
    energy_scale: float = 0.0
    max_energy_rise: float = -math.inf
    max_impact_energy_rise: float = -math.inf
    max_impact_energy_rise_step: int = 0
    impact_steps: int = 0
    chained_steps: int = 0
    first_chain: tuple[int, int, float, float] | None = None
    recent_gaps: np.ndarray | None = None

    def start(self, energy0: float | None, kinetic0: float = 0.0) -> None:
        """The energy and the kinetic energy at t0 [J] (``None``: the model has
        no energy)."""
        if energy0 is not None:
            self.energy_initial = self.energy_last = float(energy0)
            self.energy_scale = max(abs(float(energy0)), float(kinetic0))

    def add(self, records, first_step: int, energies: np.ndarray | None = None) -> None:
        """Add consecutive steps ``first_step, first_step + 1, ...`` (NumPy
        records), with the energy and kinetic energy after each step, shape
        (steps, 2), where the model has an energy."""
        it = np.asarray(records.newton.iterations)
        if not len(it):
            return
        if not self.subproblems:
            self.subproblems = tuple(records.newton.names)
            self.iterations_sum = np.zeros(len(self.subproblems))
            self.iterations_max = np.zeros(len(self.subproblems), int)
        self.n_steps += len(it)
        self.iterations_sum += it.sum(axis=0)
        self.iterations_max = np.maximum(self.iterations_max, it.max(axis=0))
        solves = it.sum(axis=1)
        self.solves_sum += float(solves.sum())
        self.solves_max = max(self.solves_max, int(solves.max()))
        result = np.asarray(records.result)
        bad = np.nonzero(result != Result.successful)[0]
        if bad.size and not self.failed:
            self.first_result = int(result[bad[0]])
        self.failed.extend((first_step + bad).tolist())
        self.instants += int(np.sum(records.instants))
        self.fallbacks += int(np.sum(records.fallback))
        gap = np.asarray(records.gap)
        if gap.size:
            self.min_gap = min(self.min_gap, float(gap.min()))
            # a step that located its impacts and did not fall back took them in sequence
            in_sequence = (np.asarray(records.instants) > 0) & ~np.asarray(records.fallback)
            self._add_chains(gap, np.asarray(records.impulse), first_step, in_sequence)
        self.max_bilateral = max(self.max_bilateral, _absmax(records.bilateral))
        self.max_bilateral_rate = max(self.max_bilateral_rate, _absmax(records.bilateral_rate))
        if energies is not None and math.isfinite(self.energy_last):
            self._add_energies(np.asarray(energies, float), np.asarray(records.impulse), first_step)

    def _add_energies(self, energies: np.ndarray, impulse: np.ndarray, first_step: int) -> None:
        energies, kinetic = energies[:, 0], energies[:, 1]
        finite = np.isfinite(energies)
        if not finite.any():
            return
        before = np.concatenate([[self.energy_last], energies[:-1]])
        rise = energies - before
        impact = np.any(impulse[:, self.n_bilateral:] != 0.0, axis=1) if impulse.ndim == 2 else np.zeros(len(rise),
                                                                                                          bool)
        ok = finite & np.isfinite(before)
        self.energy_scale = max(self.energy_scale, float(np.abs(energies[finite]).max()),
                                float(np.nan_to_num(kinetic[finite]).max()))
        if ok.any():
            self.max_energy_rise = max(self.max_energy_rise, float(rise[ok].max()))
        hits = ok & impact
        self.impact_steps += int(impact.sum())
        if hits.any():
            i = int(np.argmax(np.where(hits, rise, -np.inf)))
            if rise[i] > self.max_impact_energy_rise:
                self.max_impact_energy_rise = float(rise[i])
                self.max_impact_energy_rise_step = first_step + i
        self.energy_last = float(energies[finite][-1]) if finite[-1] else self.energy_last

    def start_gaps(self, gap0, gap_rate0, h: float) -> None:
        """The unilateral gaps (nu,) [m] at t0 and their rates [m/s] there: the
        first rows of the history that :meth:`_add_chains` reads (the row
        before t0 extrapolated by one step h [s])."""
        gap0 = np.asarray(gap0, float)
        self.recent_gaps = np.stack([gap0 - h * np.asarray(gap_rate0, float), gap0])

    def _add_chains(self, gap: np.ndarray, impulse: np.ndarray, first_step: int,
                    in_sequence: np.ndarray | None = None) -> None:
        """Count the steps where an impact closed another contact within the
        step: a contact that takes an impulse together with another, open at
        the step's start (gap above round-off) and closing by its own motion
        (its change over the step before) by less than half its gap, yet within
        :data:`CHAIN_REACH` times the travel over the step of the contacts that
        close by their own motion (a gap that jumps, as a corner's that enters
        a bounded face, is closed by no impact) and beyond :data:`SIMULTANEOUS`
        times it (a contact closer than that touches). The step then resolves in one
        simultaneous impact what happens in sequence (a Newton's cradle whose
        gaps are shorter than a step's travel). Steps marked ``in_sequence``
        (split at their located impact instants, without a fall-back) are
        not counted."""
        nu = gap.shape[1]
        history = gap if self.recent_gaps is None else np.concatenate([self.recent_gaps, gap])
        lead = len(history) - len(gap)
        hit = impulse[:, impulse.shape[1] - nu:] != 0.0
        floor = 1e3 * np.finfo(gap.dtype).eps * max(1.0, float(np.abs(history).max()))
        several = hit.sum(axis=1) >= 2
        if in_sequence is not None:
            several &= ~in_sequence
        for i in np.nonzero(several)[0]:
            k = lead + i  # history row after this step
            if k < 2:
                continue
            start, before = history[k - 1], history[k - 2]
            own = 2.0 * start - before  # the gap at the step's end by the contact's own motion
            others = hit[i] & (start > floor) & (own > 0.5 * start)
            # the travel of the impacts that close by their own motion, per step
            approach = float(np.max(np.where(hit[i] & ~others, before - start, 0.0), initial=0.0))
            # ... within reach of it: an impact of e <= 1 at most doubles a speed (a gap that jumps, as a
            # corner's that enters a bounded face, closes no impact)
            chained = others & (start <= CHAIN_REACH * approach) & (start >= SIMULTANEOUS * approach)
            if chained.any():
                self.chained_steps += 1
                if self.first_chain is None:
                    j = int(np.argmax(chained))
                    self.first_chain = (first_step + int(i), j, float(start[j]), approach)
        self.recent_gaps = history[-2:]

    def iteration_stats(self) -> dict[str, dict[str, float | int]]:
        """Mean and max iterations (linear solves) per step of each sub-problem,
        by name, and of their total (``"linear_solves"``)."""
        n = max(self.n_steps, 1)
        stats: dict[str, dict[str, float | int]] = {
            name: {"mean": float(self.iterations_sum[i] / n), "max": int(self.iterations_max[i])}
            for i, name in enumerate(self.subproblems)}
        stats["linear_solves"] = {"mean": float(self.solves_sum / n), "max": int(self.solves_max)}
        return stats

    @property
    def has_energy(self) -> bool:
        return math.isfinite(self.energy_initial)

    def energy_stats(self) -> dict | None:
        """The energy monitors [J], or ``None`` for a model without an energy."""
        if not self.has_energy:
            return None

        def number(x):
            return float(x) if math.isfinite(x) else None

        return {"initial": self.energy_initial, "final": self.energy_last,
                "change": self.energy_last - self.energy_initial,
                "max_step_rise": number(self.max_energy_rise),
                "impact_steps": self.impact_steps,
                "max_impact_rise": number(self.max_impact_energy_rise),
                "max_impact_rise_step": self.max_impact_energy_rise_step if self.impact_steps else None}


def _absmax(x) -> float:
    x = np.asarray(x)
    return float(np.abs(x).max()) if x.size else 0.0


def invariant_warnings(totals: RunTotals, tol: Tolerances, h: float, t0: float = 0.0,
                       friction_with_restitution: bool = False) -> list[str]:
    """A named warning for each monitor past its tolerance.
    ``friction_with_restitution``: the model has frictional contacts with
    e > 0, where the energy can rise at an impact for a reason other than
    the step (the warning then names it)."""
    out = []
    if totals.min_gap < -tol.penetration:
        out.append(f"penetration: a gap reached {totals.min_gap:.3e} m (tolerance {tol.penetration:g} m)")
    if totals.max_bilateral > tol.bilateral:
        out.append(f"bilateral violation: |g| reached {totals.max_bilateral:.3e} m "
                   f"(tolerance {tol.bilateral:g} m)")
    if totals.max_bilateral_rate > tol.bilateral_rate:
        out.append(f"bilateral rate violation: |g_q v| reached {totals.max_bilateral_rate:.3e} m/s "
                   f"(tolerance {tol.bilateral_rate:g} m/s)")
    if totals.first_chain is not None:
        step, j, gap, approach = totals.first_chain
        limit = f"; resolve them in sequence with h below {h * gap / approach:.2g} s (the gap over the approach " \
                f"speed)" if approach > 0 else ""
        out.append(f"{CHAIN_WARNING}: in {totals.chained_steps} step(s), first step {step} (t = {t0 + step * h:.6g} "
                   f"s), an impact closed contact {j} (open by {gap:.3g} m at the step's start) within the step, "
                   f"and the step resolved both impacts at once: the simultaneous-impact answer, not the "
                   f"sequence of binary impacts{limit}")
    if totals.has_energy and totals.impact_steps:
        rise = totals.max_impact_energy_rise
        scale = max(totals.energy_scale, 1e-300)
        if math.isfinite(rise) and rise > tol.impact_energy * scale:
            step = totals.max_impact_energy_rise_step
            out.append(f"{ENERGY_WARNING}: the energy rose by {rise:.4g} J ({100 * rise / scale:.3g} % of "
                       f"{scale:.4g} J) in step {step} (t = {t0 + step * h:.6g} s), where a contact impulse "
                       f"acted; the step is too coarse for the motion there (tolerance "
                       f"{100 * tol.impact_energy:g} %)"
                       + ("; or: with friction, Newton's restitution (e > 0) can create energy at an impact "
                          f"that reverses a slip (Kane's paradox): {ENERGETIC_HINT}, see docs/friction.md"
                          if friction_with_restitution else ""))
    return out


def coarse_step_warning(rate: float | None, h: float, tol: Tolerances) -> str | None:
    """A warning when a body turns more than ``tol.rotation_per_step`` in one
    step at its initial angular speed ``rate`` [rad/s] (``None``: no bodies
    that turn)."""
    if rate is None or not math.isfinite(rate) or rate * h <= tol.rotation_per_step:
        return None
    return (f"coarse step: a body turns {rate * h:.3g} rad per step at its initial angular speed "
            f"({rate:.4g} rad/s, h = {h:g} s; more than {tol.rotation_per_step:g} rad); contacts may be "
            f"met at the wrong point: reduce h below {tol.rotation_per_step / rate:.2g} s")


__all__ = ["CHAIN_WARNING", "ENERGETIC_HINT", "ENERGY_WARNING", "RunTotals", "Tolerances", "coarse_step_warning",
           "default_tolerances", "invariant_warnings"]
