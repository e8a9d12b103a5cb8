"""The flexible appendage: a geometrically exact beam whose nodes' rotations
are modes the step does not resolve (ωh ≈ 2,500 at h = 5e-4 s), its tip
chattering against a stop. Each way of taking its impacts once ended in a
step that Newton converged to a spurious root (energy multiplied by 1e3 to
1e5), then thousands of failed steps (docs/impact-instants.md, *A stiff
beam's impacts*)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from nsga_jax._integrators.base import StepState
from nsga_jax._integrators.impact_instants import keep_accelerations_if_short
from nsga_jax.scenes import load_scene


def _run(**options):
    scene = load_scene("flexible_appendage", options)
    sol = scene.run(throw=False)
    return sol, np.asarray(sol.observables["energy"])


def test_impacts_at_their_instants_on_a_stiff_beam_never_blow_up():
    """The scene's defaults with ``impacts = "instants"``: every step
    converges, the energy never rises above its start, and every located
    instant gave the tip an impulse (none is found where the step's own
    motion does not reach the stop)."""
    sol, energy = _run(impacts="instants")
    assert sol.stats["failed_steps"] == 0
    assert energy.max() <= energy[0] * (1 + 1e-9)
    located = np.asarray(sol.records.instants) > 0
    assert located.sum() >= 10
    assert np.all(np.asarray(sol.records.impulse)[located, -1] > 0.0)


@pytest.mark.slow
@pytest.mark.parametrize("e, omega, impacts, contacts", [
    (0.8, 3.0, "end", "jumps"),  # the paper's step: a free-flight step's Newton found a spurious root
    (0.5, 1.5, "end", "jumps"),
    (0.2, 1.5, "end", "smooth"),  # persistent contacts: the same, in the smooth motion with held contacts
    (0.2, 3.0, "instants", "jumps"),  # a lead-in of 7e-4 h to an instant
    (0.5, 2.0, "instants", "smooth"),  # the restart a+ = v̇̃+ after each chattering impact
])
def test_each_way_of_taking_the_impacts_runs_where_it_once_blew_up(e, omega, impacts, contacts):
    sol, energy = _run(e=e, hub_omega=omega, impacts=impacts, persistent_contacts=contacts)
    assert sol.stats["failed_steps"] == 0
    assert energy.max() <= energy[0] * (1 + 1e-9)
    assert energy[-1] < energy[0]  # the stop's restitution took energy out


def test_a_short_lead_in_to_an_instant_keeps_the_accelerations_of_its_start():
    """Below ``short_fraction · h`` and ending at an instant, a sub-step
    keeps v̇̃ and a of its start; a longer one, or a remainder that ends at
    no instant, keeps its own."""
    def state(x):
        return StepState(t=jnp.zeros(()), q=jnp.full(2, x), v=jnp.full(2, x), vd=jnp.full(2, x), a=jnp.full(2, -x))

    start, new = state(1.0), state(5.0)
    for located, size, kept in ((True, 0.05, True), (True, 0.2, False), (False, 0.05, False)):
        out = keep_accelerations_if_short(new, start, jnp.asarray(located), jnp.asarray(size), 1.0, 0.1)
        expected = start if kept else new
        np.testing.assert_array_equal(out.vd, expected.vd)
        np.testing.assert_array_equal(out.a, expected.a)
        np.testing.assert_array_equal(out.q, new.q)  # q and v are the sub-step's
        np.testing.assert_array_equal(out.v, new.v)
