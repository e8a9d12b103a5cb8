"""The energetic impact law (impact_law = "energetic", DS and DSn) against
Newton's restitution: it never raises the energy of an impact with friction
and e > 0 (Kane's paradox), it is Newton's law where that creates no energy,
it keeps the contacts' constraints, and a bad value is refused by name.

Measured values come from experiments/studies/energetic_impact.py
(docs/results/friction/energetic_impact.md).
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax
from nsga_jax._cli import main
from nsga_jax._monitors import ENERGETIC_HINT, ENERGY_WARNING, RunTotals, default_tolerances, invariant_warnings
from nsga_jax.scenes import load_scene, make_scheme
from nsga_jax.system import Gravity, PlaneContact, RigidBody2D, System

H = 1e-4
A, B = 0.2, 0.1  # the block's sides [m]


def block(mu, e, omega, angle=0.5, gravity=False):
    """A 1 kg block tilted by ``angle``, falling at 1 m/s and spinning at
    ``omega`` [rad/s] (its sign sets the incidence of the slip)."""
    s = System(dim=2)  # the centre a half-diagonal and 2 mm above the floor, as in the study
    s.add_body("block", RigidBody2D(1.0, (A * A + B * B) / 12, position=[0.0, 0.5 * np.hypot(A, B) + 0.002],
                                    angle=angle, velocity=[0.0, -1.0], angular_velocity=omega))
    s.add_contact("floor", PlaneContact("block", normal=[0.0, 1.0], origin=[0.0, 0.0], e=e, mu=mu,
                                        points=[[-A / 2, -B / 2], [A / 2, -B / 2], [A / 2, B / 2], [-A / 2, B / 2]]))
    if gravity:
        s.add_force("g", Gravity([0.0, -9.81]))
    return s.model()


def ball(mu, e, vx):
    """A solid ball (2D, r = 0.1 m, 1 kg) 2 mm above the floor, falling at 2 m/s, sliding at vx."""
    s = System(dim=2)
    s.add_body("ball", RigidBody2D(1.0, 0.004, position=[0.0, 0.102], velocity=[vx, -2.0]))
    s.add_contact("floor", PlaneContact("ball", normal=[0.0, 1.0], origin=[0.0, 0.0], e=e, radius=0.1, mu=mu))
    return s.model()


def run(model, scheme, t_end=0.06):
    q0, v0 = model.initial_state()
    return nsga_jax.simulate(model, scheme, 0.0, t_end, H, q0, v0)


def energy(model, sol):
    return np.asarray(jax.vmap(model.energy)(sol.q, sol.v))


def impact_steps(sol):
    return np.nonzero(np.asarray(sol.impulse).sum(axis=1) > 0)[0]


# (mu, e, omega, angle): two incidences of the spin, several coefficients and tilts
BLOCKS = [(0.5, 1.0, 20.0, 0.5), (0.5, 1.0, -20.0, 0.5), (0.5, 0.5, 20.0, 0.5), (0.3, 0.8, -20.0, 0.5),
          (1.0, 1.0, 20.0, 0.3), (0.2, 1.0, -30.0, 1.0)]


@pytest.mark.parametrize("mu, e, omega, angle", BLOCKS)
def test_energy_never_rises_at_the_spinning_blocks_impacts(mu, e, omega, angle):
    """Without gravity the energy is the kinetic energy, and the energetic law
    never raises it, at the impact or at any step after (measured: -6.5e-12 of
    it at the first impact with mu = 0.5, e = 1, where Newton's law gains 19 %)."""
    model = block(mu, e, omega, angle)
    sol = run(model, nsga_jax.DS(impact_law="energetic"))
    assert len(sol.failed_steps) == 0 and len(impact_steps(sol)) > 0
    E = energy(model, sol)
    assert np.diff(E).max() <= 1e-9 * E[0]
    assert not any(w.startswith(ENERGY_WARNING) for w in sol.warnings)


def test_newtons_law_creates_energy_where_the_energetic_law_does_not():
    """The reproduction of Kane's paradox: mu = 0.5, e = 1, at both incidences
    Newton's law gains 19 % and 56 % in the impact step (no gravity); the
    energetic law keeps the energy (to 1e-9) and changes the velocities."""
    for omega, gain in ((20.0, 0.19), (-20.0, 0.55)):
        model = block(0.5, 1.0, omega)
        with pytest.warns(nsga_jax.InvariantWarning, match="Kane's paradox"):
            newton = run(model, nsga_jax.DS())
        energetic = run(model, nsga_jax.DS(impact_law="energetic"))
        k = impact_steps(newton)[0]
        assert impact_steps(energetic)[0] == k
        En, Ee = energy(model, newton), energy(model, energetic)
        assert (En[k] - En[k - 1]) / En[k - 1] > gain
        assert abs(Ee[k] - Ee[k - 1]) <= 1e-9 * Ee[k - 1]
        assert np.abs(np.asarray(energetic.v[k] - newton.v[k])).max() > 0.1


def test_dsn_carries_the_law_and_gravity_leaves_the_steps_own_error():
    """DSn (no f* term) gives DS's jump on the rigid block; with gravity the
    impact step keeps the scheme's own error (the position correction lifts
    the block out of the floor: +2.9e-4 of the energy at h = 1e-4 s, where
    Newton's law gains 13 %), far below the 1 % warning."""
    model = block(0.5, 1.0, 20.0)
    ds, dsn = (run(model, cls(impact_law="energetic")) for cls in (nsga_jax.DS, nsga_jax.DSn))
    np.testing.assert_allclose(np.asarray(dsn.v), np.asarray(ds.v), atol=1e-9)
    heavy = block(0.5, 1.0, 20.0, gravity=True)
    sol = run(heavy, nsga_jax.DSn(impact_law="energetic"), t_end=0.03)
    E = energy(heavy, sol)
    k = impact_steps(sol)[0]
    assert 0.0 < (E[k] - E[k - 1]) / E[k - 1] < 1e-3
    assert sol.warnings == []


@pytest.mark.parametrize("model", [ball(None, 0.8, 1.0), block(1.0, 0.0, 20.0), ball(0.1, 0.8, 2.0),
                                   ball(0.5, 0.8, 0.0)],
                         ids=["frictionless", "sticking_e0", "sliding_no_reversal", "no_slip"])
def test_equal_to_newtons_law_where_it_creates_no_energy(model):
    """Frictionless (traced as Newton's law), friction with e = 0 (the
    compression jump is Newton's), a ball sliding through its impact (its
    restitution releases more than e² of nothing it must not: Newton's jump
    keeps within the bound) and a frictional impact without slip: the
    energetic law returns Newton's trajectory bit for bit."""
    newton = run(model, nsga_jax.DS(), t_end=0.03)
    energetic = run(model, nsga_jax.DS(impact_law="energetic"), t_end=0.03)
    assert len(impact_steps(newton)) > 0
    np.testing.assert_array_equal(np.asarray(energetic.q), np.asarray(newton.q))
    np.testing.assert_array_equal(np.asarray(energetic.v), np.asarray(newton.v))


def test_constraints_hold_after_the_impact():
    """After the capped impact the block does not penetrate (position
    correction), the corners that took an impulse separate or stay
    (g_q v⁺ >= 0) and every friction impulse is within Coulomb's cone."""
    model = block(0.5, 1.0, -20.0)
    sol = run(model, nsga_jax.DS(impact_law="energetic"))
    assert sol.stats["max_penetration"] <= 1e-9
    normal = np.asarray(sol.impulse)
    tangential = np.abs(np.asarray(sol.records.friction))
    assert np.all(tangential <= 0.5 * normal * (1 + 1e-9) + 1e-12)
    for k in impact_steps(sol):
        rates = np.asarray(model.constraint_jacobian(sol.q[k]) @ sol.v[k])
        assert np.all(rates[normal[k] > 0] >= -1e-9)


def test_the_share_is_differentiable():
    """jax.grad through the capped impact (nsga_jax.integrate, the discrete
    adjoint) against central finite differences of the same run."""
    model = block(0.5, 1.0, 20.0)
    q0, v0 = model.initial_state()
    n = 150  # the impact is at step 107

    def final_spin(w):
        v = v0.at[2].set(w)
        sol = nsga_jax.integrate(model, nsga_jax.DS(impact_law="energetic"), 0.0, n * H, H, q0, v, n_steps=n)
        return sol.v[-1, 2]

    grad = float(jax.grad(final_spin)(jnp.asarray(20.0)))
    eps = 1e-4
    fd = float((final_spin(20.0 + eps) - final_spin(20.0 - eps)) / (2 * eps))
    assert np.isfinite(grad) and grad == pytest.approx(fd, rel=1e-4, abs=1e-6)


# ------------------------------------------------------------- the option's reach

def test_bad_values_are_refused_by_name():
    model = ball(0.5, 0.8, 1.0)
    q0, v0 = model.initial_state()
    with pytest.raises(nsga_jax.ConfigError, match="impact_law must be one of 'newton', 'energetic', got 'stronge'"):
        nsga_jax.simulate(model, nsga_jax.DS(impact_law="stronge"), 0.0, 0.01, H, q0, v0)
    with pytest.raises(nsga_jax.ConfigError, match="impact_law must be one of"):
        nsga_jax.integrate(model, nsga_jax.DSn(impact_law=1), 0.0, 0.01, H, q0, v0)
    for scheme in ("cs", "mj"):
        with pytest.raises(nsga_jax.ConfigError, match=f"impact_law = 'energetic' .* scheme = '{scheme}'"):
            load_scene("bouncing_ball", {"impact_law": "energetic", "scheme": scheme})
    with pytest.raises(TypeError, match="impact_law"):  # CS and MJ have no such field
        nsga_jax.CS(impact_law="energetic")  # type: ignore[call-arg]
    with pytest.raises(nsga_jax.ConfigError, match="impact_law must be one of 'newton', 'energetic', got 'Newton'"):
        load_scene("bouncing_ball", {"impact_law": "Newton"})


def test_system_files_configs_and_the_command_line_reach_the_option(tmp_path, capsys):
    path = tmp_path / "spinning_block.toml"
    path.write_text("""
[system]
dim = 2
[bodies.block]
type = "rigid_body_2d"
mass = 1.0
inertia = 0.004166666666666667
position = [0.0, 0.1138]
angle = 0.5
velocity = [0.0, -1.0]
angular_velocity = 20.0
[contacts.floor]
type = "plane"
body = "block"
normal = [0.0, 1.0]
origin = [0.0, 0.0]
e = 1.0
mu = 0.5
points = [[-0.1, -0.05], [0.1, -0.05], [0.1, 0.05], [-0.1, 0.05]]
[solver]
h = 1e-4
t_end = 0.03
impact_law = "energetic"
""")
    scene = load_scene(path)
    assert make_scheme(scene.solver) == nsga_jax.DS(impact_law="energetic")
    assert make_scheme(load_scene(path, {"impact_law": "newton"}).solver) == nsga_jax.DS()
    assert make_scheme(load_scene("rigid_box", {"impact_law": "energetic", "scheme": "dsn"}).solver) == \
        nsga_jax.DSn(impact_law="energetic")
    bad = path.read_text().replace('impact_law = "energetic"', 'impact_law = "poisson"')
    path.write_text(bad)
    with pytest.raises(nsga_jax.ConfigError, match="solver.impact_law must be one of 'newton', 'energetic', got "
                                                   "'poisson'"):
        load_scene(path)
    assert main(["run", str(path), "--impact-law", "stronge"]) == 2  # argparse names the choices
    assert "--impact-law" in capsys.readouterr().err
    assert main(["run", "bouncing_ball", "--impact-law", "energetic", "--scheme", "mj", "--out",
                 str(tmp_path / "out")]) == 2
    assert "impact_law = 'energetic'" in capsys.readouterr().err


def test_the_warning_names_the_option():
    """Newton's law on the spinning block warns of Kane's paradox and names
    the option (the run with the option has nothing to warn of:
    test_energy_never_rises_at_the_spinning_blocks_impacts)."""
    with pytest.warns(nsga_jax.InvariantWarning) as record:
        sol = run(block(0.5, 1.0, 20.0), nsga_jax.DS())
    (message,) = [w for w in sol.warnings if w.startswith(ENERGY_WARNING)]
    assert "Kane's paradox" in message and ENERGETIC_HINT in message
    assert any('impact_law = "energetic"' in str(w.message) for w in record)
    for reach in ('impact_law = "energetic"', 'DS(impact_law="energetic")', "[solver] impact_law",
                  "--impact-law energetic"):
        assert reach in ENERGETIC_HINT


def test_the_warning_leaves_the_option_out_where_it_cannot_help():
    """Without friction (or with e = 0) a rise at an impact is the step's,
    and the warning names no impact law."""
    totals = RunTotals(energy_initial=1.0, energy_last=1.5, energy_scale=1.0, max_impact_energy_rise=0.5,
                       max_impact_energy_rise_step=3, impact_steps=1)
    tol = default_tolerances()
    (with_friction,) = invariant_warnings(totals, tol, 1e-3, friction_with_restitution=True)
    (without,) = invariant_warnings(totals, tol, 1e-3, friction_with_restitution=False)
    assert ENERGETIC_HINT in with_friction and "impact_law" not in without


def test_the_impact_time_adjoint_refuses_the_energetic_law_with_friction():
    """The impact-time rebuild applies Newton's law: with friction it would be the
    derivative of another law than the run's, so it is refused by name while
    tracing; with Newton's law it traces."""
    nj = nsga_jax
    scene = load_scene("incline", {"mu": 0.2, "t_end": 0.01})

    def run(scheme):
        return nj.integrate(scene.model, scheme, 0.0, 0.01, 1e-3, scene.q0, scene.v0,
                            adjoint=nj.ImpactTimeAdjoint()).q[-1, 0]

    with pytest.raises(nj.ConfigError, match=r"ImpactTimeAdjoint rebuilds an impact with Newton's law, not the "
                                             r"impact_law = 'energetic' of DS .* use DiscreteAdjoint\(\)"):
        jax.eval_shape(lambda: run(nj.DS(impact_law="energetic")))
    jax.eval_shape(lambda: run(nj.DS()))  # Newton's law: traced without complaint
