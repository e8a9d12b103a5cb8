"""Coulomb friction against exact solutions: a box sliding to rest (2D and 3D,
along an axis and a diagonal), a block on an incline below and above the
friction angle, mu = 0 against frictionless contacts, oblique impacts of a
point mass, a glancing impact of two discs, and the gradient of the sliding
distance. Every run with friction checks that the energy never grows.

Measured values quoted below come from experiments/studies/friction_convergence.py
(docs/results/friction/).
"""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax
from nsga_jax._elements.rigid_body import box_inertia, box_vertices
from nsga_jax.scenes import load_scene
from nsga_jax.system import Gravity, PlaneContact, PointMass, RigidBody2D, RigidBody3D, SphereContact, System

G, MU, V0 = 9.81, 0.3, 2.0
D_EXACT, T_EXACT = V0**2 / (2 * MU * G), V0 / (MU * G)  # sliding distance [m] and time [s]
SCHEMES = {"DS": nsga_jax.DS(), "DSn": nsga_jax.DSn(), "CS": nsga_jax.CS(), "MJ": nsga_jax.MJ()}
ALL = pytest.mark.parametrize("scheme", list(SCHEMES))
CHEAP = pytest.mark.parametrize("scheme", ["DS", "MJ"])
# Tests of 20 s or more on a 2-core machine carry pytest.mark.slow (run by `pytest -m slow`).


def run(model, scheme, t_end, h, **kwargs):
    q0, v0 = model.initial_state()
    sol = nsga_jax.simulate(model, SCHEMES[scheme] if isinstance(scheme, str) else scheme, 0.0, t_end, h, q0, v0,
                            **kwargs)
    assert len(sol.failed_steps) == 0
    return sol


def assert_energy_never_grows(model, sol, rtol=1e-12):
    """E(t_{n+1}) <= E(t_n) + round-off at every step [J]."""
    energy = np.asarray(jax.vmap(model.energy)(sol.q, sol.v))
    scale = max(1.0, float(np.abs(energy).max()))
    assert float(np.diff(energy).max()) <= rtol * scale * 10, float(np.diff(energy).max())


def box_2d(v0=V0, mu=MU, angle=0.0, sink=0.0):
    """A 0.2 m x 0.1 m box of 1 kg resting on its long face on the floor through
    the origin with normal (-sin a, cos a), launched at v0 [m/s] along it
    (coordinates x, y, angle); ``sink`` [m] presses it into the floor."""
    n = jnp.stack([-jnp.sin(angle), jnp.cos(angle)])
    t = jnp.stack([jnp.cos(angle), jnp.sin(angle)])
    s = System(dim=2)
    s.add_body("box", RigidBody2D(1.0, (0.2**2 + 0.1**2) / 12, position=(0.05 - sink) * n, angle=angle,
                                  velocity=v0 * t))
    s.add_contact("floor", PlaneContact("box", normal=n, origin=[0.0, 0.0], e=0.0,
                                        points=[[-0.1, -0.05], [0.1, -0.05]], mu=mu))
    s.add_force("g", Gravity([0.0, -G]))
    return s.model()


def box_3d(velocity, mu=MU):
    """A 0.2 x 0.1 x 0.1 m box of 1 kg resting on its four lower vertices,
    launched horizontally at ``velocity`` (3,) [m/s] (natural coordinates:
    centre (3), then the rotation matrix's columns (9))."""
    sides = jnp.array([0.2, 0.1, 0.1])
    vertices = box_vertices(sides)
    s = System(dim=3)
    s.add_body("box", RigidBody3D(1.0, box_inertia(1.0, sides), position=[0.0, 0.0, 0.05], velocity=velocity))
    s.add_contact("floor", PlaneContact("box", normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, 0.0], e=0.0,
                                        points=vertices[np.asarray(vertices[:, 2]) < 0], mu=mu))
    s.add_force("g", Gravity([0.0, 0.0, -G]))
    return s.model()


def check_slide_and_rest(model, sol, h, plane: slice, direction):
    """The box slides along ``direction`` only, stops in the first step after
    T = v0/(mu g) and then rests: no drift, no rotation, no vertical motion.
    Returns the distance error [m]."""
    q, v, ts = np.asarray(sol.q), np.asarray(sol.v), np.asarray(sol.ts)
    speed = np.linalg.norm(v[:, plane], axis=1)
    at_rest = int(np.argmax(speed <= 1e-9))
    assert 0.0 <= ts[at_rest] - T_EXACT < h + 1e-12  # the first step time past T
    assert np.all(speed[at_rest:] <= 1e-9)
    displacement = q[:, plane] - q[0, plane]
    # the motion stays on the line of the launch velocity
    across = displacement - np.outer(displacement @ direction, direction)
    assert np.abs(across).max() < 1e-9  # Newton-tolerance level (measured 5.8e-11 m across 0.68 m in 3D)
    # rest: the position is constant to round-off over the remaining 0.8 s
    assert np.ptp(q[at_rest:, plane], axis=0).max() < 1e-12
    # no rotation and no vertical motion at any time
    vertical = 1 if model.dim == 2 else 2
    assert np.ptp(q[:, vertical]) < 1e-12
    rotation = q[:, 2] if model.dim == 2 else q[:, 3:]
    assert np.abs(rotation - rotation[0]).max() < 1e-12
    assert_energy_never_grows(model, sol)
    return float(np.linalg.norm(displacement[-1])) - D_EXACT


# Observed distance errors (friction_convergence.py): every scheme integrates the sliding phase
# exactly at the step times (DS, DSn and CS through Coulomb's law in the position correction, MJ
# through its trapezoidal position update); the error comes from the stopping step only,
# |error| <= mu g h² / 8 (order about 2, with a factor that depends on where T falls in a step).
DISTANCE_BOUND = {k: (lambda h: 1.01 * MU * G * h**2 / 8) for k in SCHEMES}
LADDER = (4e-3, 2e-3, 1e-3)


@pytest.mark.parametrize("scheme", ["DS", "MJ", *(pytest.param(k, marks=pytest.mark.slow) for k in ("DSn", "CS"))])
def test_2d_box_slides_stops_and_rests(scheme):
    model = box_2d()
    errors = []
    for h in LADDER:
        sol = run(model, scheme, 1.5, h)
        errors.append(check_slide_and_rest(model, sol, h, slice(0, 1), np.array([1.0])))
        ts, x = np.asarray(sol.ts), np.asarray(sol.q[:, 0])
        sliding = ts < T_EXACT - h  # the steps before the stopping step: x = v0 t - mu g t²/2 at the step times
        assert np.abs(x[sliding] - (V0 * ts[sliding] - 0.5 * MU * G * ts[sliding] ** 2)).max() < 1e-12
    for h, e in zip(LADDER, errors):
        assert abs(e) <= DISTANCE_BOUND[scheme](h), (h, e)




MJ_FAILS_AT_REST = [pytest.mark.slow, pytest.mark.xfail(strict=True, reason=(
    "MJ's Newton iteration fails a few steps at rest on the four vertices after the stop (2 steps at "
    "h = 1 ms with v0 = 1 m/s, at the iteration cap); DS, DSn and CS take one to three iterations"))]


@pytest.mark.parametrize("direction", ["x", "diagonal"])
@pytest.mark.parametrize("scheme", [*(pytest.param(k, marks=pytest.mark.slow) for k in ("DS", "DSn", "CS")),
                                    pytest.param("MJ", marks=MJ_FAILS_AT_REST)])
def test_3d_box_slides_stops_and_rests(scheme, direction):
    """On the friction disk: a launch along x or along the diagonal keeps its
    direction and stops after v0²/(2 mu g), to the stopping step's O(h²).

    The Newton tolerance is tight (tol_r = 1e-10) so that "no rotation" can be
    asserted to round-off: in the last steps before the stop the disk
    projection converges in two iterations to eq. 51's default bound, which
    leaves rotational velocities of its size (1.5e-7 1/s, 1.6e-9 in the
    rotation matrix at h = 2e-3)."""
    u = np.array([1.0, 0.0]) if direction == "x" else np.array([1.0, 1.0]) / np.sqrt(2)
    model = box_3d([V0 * u[0], V0 * u[1], 0.0])
    errors = []
    for h in (2e-3, 1e-3):
        sol = run(model, type(SCHEMES[scheme])(tol_r=1e-10), 1.2, h)
        errors.append(check_slide_and_rest(model, sol, h, slice(0, 2), u))
    assert abs(errors[0]) <= DISTANCE_BOUND[scheme](2e-3) and abs(errors[1]) <= DISTANCE_BOUND[scheme](1e-3), errors


MJ_OPEN_CORNERS = ("MJ's first step on the tilted floor finds the corners open (gaps a round-off above zero): at "
                   "a = 0.35 the block falls freely for a step, at a = 0.25 it presses on one corner only, rocks, "
                   "penetrates by 1.7e-5 m and moves 1.6e-5 m before it settles; pressed in by 1e-12 m it starts "
                   "as it should")
MJ_FIRST_STEP = {0.35: pytest.mark.xfail(strict=True, reason=MJ_OPEN_CORNERS),
                 0.25: pytest.mark.xfail(  # set before collection by conftest.py's pytest_configure
                     "xla_backend_optimization_level=0" not in os.environ.get("XLA_FLAGS", ""), strict=True,
                     reason=MJ_OPEN_CORNERS + " (at a = 0.25 the gaps' last bits follow the compiler's rounding: "
                     "compiled without LLVM's optimisations, as in the default suite, they come out closed and "
                     "the block must rest)")}
INCLINE = [("DS", 0.25, 0.3, 0.0), ("DS", 0.29, 0.3, 0.0), ("DS", 0.35, 0.3, 0.0), ("DS", 0.5, 0.3, 0.0),
           ("DSn", 0.29, 0.3, 0.0), ("CS", 0.29, 0.3, 0.0),
           *(pytest.param("MJ", a, 0.3, 0.0, marks=MJ_FIRST_STEP[a]) for a in (0.25, 0.35)),
           *(("MJ", a, 0.3, 1e-12) for a in (0.25, 0.29, 0.35, 0.5))]


@pytest.mark.parametrize("scheme, angle, mu, sink", INCLINE)
def test_block_on_an_incline(scheme, angle, mu, sink):
    """tan a <= mu: the block stays where it is put (no creep over 2 s);
    otherwise it slides down at g (sin a - mu cos a) from rest. MJ's first
    step on a floor it touches to round-off is reported in its mark."""
    model = box_2d(v0=0.0, mu=mu, angle=angle, sink=sink)
    h = 1e-3
    tangent = np.array([np.cos(angle), np.sin(angle)])
    if np.tan(angle) <= mu:
        sol = run(model, scheme, 2.0, h)
        q = np.asarray(sol.q)
        assert np.abs(q[:, :2] - q[0, :2]).max() < 1e-12
        assert np.abs(q[:, 2] - angle).max() < 1e-12
    else:
        sol = run(model, scheme, 0.5, h)
        ts, v = np.asarray(sol.ts), np.asarray(sol.v)
        exact = -G * (np.sin(angle) - mu * np.cos(angle)) * ts
        np.testing.assert_allclose(v[:, :2] @ tangent, exact, atol=1e-10 * G)
        assert np.abs(v[:, :2] @ np.array([-np.sin(angle), np.cos(angle)])).max() < 1e-12
        assert np.abs(v[:, 2]).max() < 1e-12
    assert_energy_never_grows(model, sol)


@pytest.mark.slow
@ALL
def test_zero_mu_reproduces_frictionless_contacts(scheme):
    """The paper's spinning rigid box (§4.1) with mu = 0 given as a traced zero
    (friction rows present, every tangential impulse zero) follows the
    frictionless run to the Newton tolerance: the frictional velocity jump is
    solved through a contact-space system of normal and tangential unknowns
    where the frictionless one is not, so their round-off differs, and the
    iterations, stopped at eq. 51's bound, carry that difference (CS: 5.1e-11
    m/s and 1.3e-12 m apart over 0.69 s, with or without damped updates).
    DS and DSn: the four corners landing flat make the contact system
    singular, and its solution extrapolated to no null-space part
    (docs/friction.md, *Settling on redundant contacts*) passes eq. 51 after
    one iteration a little less exactly than the frictionless solve: 5.3e-8
    m/s (1.3e-9 of the box's speed), 1.1e-9 m and 1.2e-10 in energy apart."""
    scene = load_scene("rigid_box")
    model, q0, v0 = scene.model, scene.q0, scene.v0
    frictional = rebuild_with_mu(model, jnp.zeros(()))
    assert frictional.n_friction == 8 and model.n_friction == 0
    h, t_end = 1e-3, 0.69
    a = nsga_jax.simulate(model, SCHEMES[scheme], 0.0, t_end, h, q0, v0)
    b = nsga_jax.simulate(frictional, SCHEMES[scheme], 0.0, t_end, h, q0, v0)
    assert len(a.failed_steps) == len(b.failed_steps) == 0
    # velocities within the Newton tolerance of each other; positions within h times that per step
    atol_v = 1e-9 if scheme in ("CS", "MJ") else 1e-7
    np.testing.assert_allclose(np.asarray(b.v), np.asarray(a.v), rtol=0, atol=atol_v)
    np.testing.assert_allclose(np.asarray(b.q), np.asarray(a.q), rtol=0, atol=atol_v * t_end)
    assert np.abs(np.asarray(b.records.friction)).max() < 1e-12
    # the frictionless run's energy is not monotone for the generalized-alpha schemes (DS, DSn, CS
    # gain up to 3.5 J of 2284 J in a step at h = 1 ms); with mu = 0 it is the same energy
    energy_a = np.asarray(jax.vmap(model.energy)(a.q, a.v))
    energy_b = np.asarray(jax.vmap(frictional.energy)(b.q, b.v))
    np.testing.assert_allclose(energy_b, energy_a, rtol=1e-12 if scheme in ("CS", "MJ") else 1e-9)
    if scheme == "MJ":
        assert_energy_never_grows(frictional, b, rtol=1e-9)


def rebuild_with_mu(model, mu):
    """``model`` with its plane contacts given the friction coefficient ``mu``."""
    import equinox as eqx

    planes = [i for i, c in enumerate(model.contacts) if isinstance(c, PlaneContact)]
    assert planes
    contacts = tuple(eqx.tree_at(lambda c: c.mu, c, mu, is_leaf=lambda x: x is None) if i in planes else c
                     for i, c in enumerate(model.contacts))
    return eqx.tree_at(lambda m: m.contacts, model, contacts)


def point_mass(position, velocity, mu, e, gravity):
    """A 1 kg point mass above the floor through the origin (normal up)."""
    dim = len(position)
    up = np.eye(dim)[-1]
    s = System(dim=dim)
    s.add_body("ball", PointMass(1.0, position=position, velocity=velocity))
    s.add_contact("floor", PlaneContact("ball", normal=up, origin=np.zeros(dim), e=e, mu=mu))
    if gravity:
        s.add_force("g", Gravity(-G * up))
    return s.model()


@CHEAP
@pytest.mark.parametrize("tangential", [[2.0], [0.3], [1.2, 1.6], [0.24, 0.32]],
                         ids=["2d-slip", "2d-stick", "3d-slip", "3d-stick"])
def test_oblique_impact_of_a_point_mass(scheme, tangential):
    """An oblique impact (no gravity, e = 0.5, mu = 0.3) on the floor: the
    normal velocity turns into e |v_n|, the tangential speed into
    max(0, |v_t| - mu (1 + e) |v_n|) in the direction of v_t (the impulse law
    of a point mass, |P_T| = mu P_N while it slips)."""
    e, mu, vn = 0.5, 0.3, 1.0
    vt = np.asarray(tangential)
    model = point_mass([*(0.0 * vt), 0.1037], [*vt, -vn], mu, e, gravity=False)  # hits the floor at t = 0.1037 s
    sol = run(model, scheme, 0.2, 1e-3)
    v = np.asarray(sol.v)
    speed = max(0.0, np.linalg.norm(vt) - mu * (1 + e) * vn)
    np.testing.assert_allclose(v[-1, :-1], speed * vt / np.linalg.norm(vt), atol=1e-10)
    np.testing.assert_allclose(v[-1, -1], e * vn, atol=1e-10)
    assert speed == 0.0 or speed > 0.5  # the cases are on either side of the stick limit
    assert_energy_never_grows(model, sol)


@CHEAP
def test_3d_point_mass_keeps_its_sliding_direction(scheme):
    """Isotropy of the friction disk: a point mass sliding on the floor along
    (3, 4)/5 decelerates at mu g along that line and stops at T = v0/(mu g)."""
    u = np.array([0.6, 0.8])
    model = point_mass([0.0, 0.0, 0.0], [*(V0 * u), 0.0], MU, 0.0, gravity=True)
    h = 1e-3
    sol = run(model, scheme, 1.0, h)
    q, v, ts = np.asarray(sol.q), np.asarray(sol.v), np.asarray(sol.ts)
    across = v[:, :2] @ np.array([-u[1], u[0]])
    assert np.abs(across).max() < 1e-9 and np.abs(q[:, :2] @ np.array([-u[1], u[0]])).max() < 1e-12
    sliding = ts < T_EXACT - h
    np.testing.assert_allclose((v[:, :2] @ u)[sliding], V0 - MU * G * ts[sliding], atol=1e-10)
    assert np.abs(v[ts > T_EXACT + h]).max() < 1e-12
    assert np.abs(q[:, 2]).max() < 1e-12
    assert_energy_never_grows(model, sol)


def two_discs(mu, e=0.5, offset=0.15):
    """Two discs of radius 0.1 m (1 kg and 2 kg, uniform): a at the origin
    moving at 2 m/s along x, b at rest at (0.3, offset); no gravity."""
    s = System(dim=2)
    s.add_body("a", RigidBody2D(1.0, 0.5 * 1.0 * 0.1**2, position=[0.0, 0.0], velocity=[2.0, 0.0]))
    s.add_body("b", RigidBody2D(2.0, 0.5 * 2.0 * 0.1**2, position=[0.3, offset]))
    s.add_contact("touch", SphereContact("a", "b", 0.1, 0.1, e, mu=mu))
    return s.model()


@CHEAP
def test_glancing_impact_of_two_discs(scheme):
    """A glancing impact of two discs: at every step the tangential impulse
    is bounded by mu times the normal one (and reaches it: the discs slip),
    the linear momentum m_a v_a + m_b v_b is conserved, the energy never
    grows, and both discs spin. (The angular momentum about the origin is not
    kept exactly: the two discs' contact points differ by the gap at the
    impact step, so the tangential impulse's moments differ by gap x P_T,
    1.9e-4 kg m²/s here.)"""
    mu = 0.2
    model = two_discs(mu)
    sol = run(model, scheme, 0.2, 1e-3)
    v = np.asarray(sol.v)
    P_N, P_T = np.asarray(sol.records.impulse)[:, 0], np.asarray(sol.records.friction)[:, 0]
    assert np.all(np.abs(P_T) <= mu * P_N * (1 + 1e-9) + 1e-14)
    k = int(np.argmax(P_N))
    assert P_N[k] > 0.5 and abs(P_T[k]) > 0.99 * mu * P_N[k]  # one impact, slipping throughout
    masses = np.array([1.0, 2.0])
    momentum = masses[0] * v[:, 0:2] + masses[1] * v[:, 3:5]
    np.testing.assert_allclose(momentum, np.broadcast_to(momentum[0], momentum.shape), atol=1e-12)
    assert abs(v[-1, 2]) > 0.1 and abs(v[-1, 5]) > 0.1
    assert_energy_never_grows(model, sol)


def final_x(p, h, n, scheme, adjoint):
    """The 2D box's x [m] after n steps of h, p = (mu, v0)."""
    model = box_2d(v0=p[1], mu=p[0])
    q0, v0 = model.initial_state()
    return nsga_jax.integrate(model, scheme, 0.0, n * h, h, q0, v0, n_steps=n, adjoint=adjoint).q[-1, 0]


@pytest.mark.slow
@pytest.mark.parametrize("adjoint", [nsga_jax.DiscreteAdjoint(), nsga_jax.ImpactTimeAdjoint()],
                         ids=["discrete", "impact-time"])
def test_gradient_of_the_sliding_distance(adjoint):
    """d = v0²/(2 mu g): d(d)/d(mu) = -v0²/(2 mu² g), d(d)/d(v0) = v0/(mu g).

    The gradient of the final x of a DS run (h = 1 ms, 1 s: at rest after
    T = 0.6796 s) equals central finite differences of the same discrete run
    to 1e-6 and the closed forms to O(h) (measured at h = 1e-3: relative
    2.3e-4 in mu, 6.2e-4 in v0). What the gradient is at the stick–slip
    switch: the discrete run slides for a whole number N of steps, and x is a
    smooth function of (mu, v0) for each N; the gradient is that piece's
    derivative. d(x)/d(v0) is exactly the sliding time on the grid, N h,
    with N h the step time nearest T (0.680 s against T = 0.6796 s): the
    position correction takes the last step's slip by the midpoint rule, so
    the run stops in the step whose midpoint T passes (MJ's derivative is
    (N - 1/2) h with N h the first step time past T). Where T crosses a
    half-step time (v0* = 680.5 h mu g here) N grows by one: x stays
    continuous (no jump in the value, so no jump term is missing) but its
    derivative jumps by h, from 0.680 to 0.681: x(v0) is piecewise smooth
    with kinks h mu g apart in v0, and the gradient is a staircase within h/2
    of the exact v0/(mu g). Both adjoints give the same gradient here (no
    contact closes: the box rests on the floor from the start)."""
    scheme = nsga_jax.DS(tol_r=1e-12, tol_f=1e-12)
    h, n = 1e-3, 1000
    p = jnp.array([MU, V0])
    value = jax.jit(lambda p: final_x(p, h, n, scheme, adjoint))
    grad_fn = jax.jit(jax.grad(lambda p: final_x(p, h, n, scheme, adjoint)))
    grad = np.asarray(grad_fn(p))
    fd = np.array([(float(value(p.at[k].mul(1 + 1e-6))) - float(value(p.at[k].mul(1 - 1e-6)))) / (2e-6 * float(p[k]))
                   for k in range(2)])
    np.testing.assert_allclose(grad, fd, rtol=1e-6)
    t_grid = np.round(T_EXACT / h) * h
    np.testing.assert_allclose(grad[1], t_grid, rtol=1e-9)
    assert abs(grad[1] - V0 / (MU * G)) <= h / 2
    # -v0²/(2 mu² g) = -g T²/2: a sliding time off by at most h moves it by at most g T h
    assert abs(grad[0] + V0**2 / (2 * MU**2 * G)) <= G * T_EXACT * h
    # across the switch at v0* (T = 0.6805 s on a half-step time): continuous value, derivative up by h
    v_star, delta = 680.5 * h * MU * G, 1e-7
    below, above = jnp.array([MU, v_star - delta]), jnp.array([MU, v_star + delta])
    np.testing.assert_allclose([float(grad_fn(below)[1]), float(grad_fn(above)[1])], [0.680, 0.681], rtol=1e-9)
    assert abs(float(value(above)) - float(value(below))) <= 2 * delta * 0.681 + 1e-12
