"""Impacts at their instants (``DS(impact_instants=True)``): exact bounces,
energy kept by elastic impacts, second order through impacts, rest after an
accumulation, the same run from every driver, gradients through the located
instant, and refusals by name."""

import math
import warnings

import jax
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax._batch import simulate_batch
from nsga_jax._exact import (
    bouncing_ball,
    bouncing_ball_impacts,
    newtons_cradle,
    newtons_cradle_collisions,
    rocking_impact_times,
)
from nsga_jax._metrics import energy_through_impacts, first_rebound
from nsga_jax.scenes import load_scene, parametrize

G = 9.81


def _ball(e, height=1.0):
    return load_scene("bouncing_ball", {"e": e, "height": height, "gravity": G})


def _energy(sol):
    return 0.5 * sol.v[:, 0] ** 2 + G * sol.q[:, 0]


@pytest.mark.parametrize("scheme", ["DS", "DSn"])
def test_elastic_ball_keeps_its_energy_and_its_apex(scheme):
    """e = 1, ρ∞ = 1, h = 1e-3 over 20 s (22 bounces): the energy to round-off
    and every impact resolved at its instant; the paper's step loses g h of
    speed at the first bounce and keeps the loss."""
    ball = _ball(1.0)
    cls = getattr(nj, scheme)
    sol = nj.simulate(ball.model, cls(rho_inf=1.0, impact_instants=True), 0.0, 20.0, 1e-3, ball.q0, ball.v0)
    energy = _energy(sol)
    assert np.abs(energy / energy[0] - 1.0).max() < 1e-9
    assert sol.q[-2000:, 0].max() > 0.999999
    impacts = len(bouncing_ball_impacts(1.0, 0.0, G, 1.0, 20.0)[0])
    assert impacts == 22
    assert sol.stats["impacts_at_instants"] == impacts and sol.stats["instant_fallbacks"] == 0
    assert sol.stats["failed_steps"] == 0
    paper = nj.simulate(ball.model, cls(rho_inf=1.0), 0.0, 20.0, 1e-3, ball.q0, ball.v0)
    assert _energy(paper)[-1] / energy[0] < 0.998
    assert paper.stats["impacts_at_instants"] == 0


@pytest.mark.parametrize("h", [2e-3, 1e-3])
def test_ball_follows_the_exact_bounces(h):
    """e = 0.8 over 3 s (six bounces): height and velocity at every step equal
    the exact solution to round-off, where the paper's step is O(1) off in
    velocity after each impact (its velocity jump comes a fraction of a step late)."""
    ball = _ball(0.8)
    sol = nj.simulate(ball.model, nj.DS(impact_instants=True), 0.0, 3.0, h, ball.q0, ball.v0)
    z, vz = bouncing_ball(sol.ts, 1.0, 0.0, G, 0.8)
    assert np.abs(sol.q[:, 0] - z).max() < 1e-9
    assert np.abs(sol.v[:, 0] - vz).max() < 1e-8
    paper = nj.simulate(ball.model, nj.DS(), 0.0, 3.0, h, ball.q0, ball.v0)
    assert np.abs(paper.v[:, 0] - vz).max() > 1.0


def test_double_pendulum_converges_at_second_order_through_its_impact():
    """The double pendulum against its event-driven reference over 1 s (one
    wall impact at t ≈ 0.6 s): observed order >= 1.8 at h = 2e-3, 1e-3,
    5e-4 (measured 2.11 and 2.08); restarting v̇̃ and a after the impact
    matters: carried across it, the order falls to about 1.2."""
    scene = load_scene("double_pendulum", {})
    errors = []
    for h in (2e-3, 1e-3, 5e-4):
        sol = nj.simulate(scene.model, nj.DS(impact_instants=True), 0.0, 1.0, h, scene.q0, scene.v0)
        assert sol.stats["impacts_at_instants"] == 1 and sol.stats["failed_steps"] == 0
        observed, exact = scene.observables(sol), scene.exact(np.asarray(sol.ts))
        errors.append(max(float(np.abs(np.asarray(observed[k]) - np.asarray(exact[k])).max())
                          for k in scene.spec.error_observables if k in exact))
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert min(orders) >= 1.8, (errors, orders)


def test_ball_coming_to_rest_resolves_its_bounces_and_rests():
    """e = 0.5 accumulates its impacts at t∞ = 3 √(2 h0 / g) = 1.355 s: the
    bounces before are resolved at their instants, and from t∞ on the ball
    rests on the floor (paper steps: a contact closed at a step's start is
    never located)."""
    ball = _ball(0.5)
    sol = nj.simulate(ball.model, nj.DS(impact_instants=True), 0.0, 3.0, 1e-3, ball.q0, ball.v0)
    assert sol.stats["failed_steps"] == 0
    assert sol.stats["impacts_at_instants"] >= 10
    rest = sol.ts > 3.0 * math.sqrt(2.0 / G) + 2e-3
    assert np.abs(sol.q[rest, 0]).max() < 1e-12
    settled = sol.ts > 3.0 * math.sqrt(2.0 / G) + 0.05  # the rest's velocity halves at each step (e = 0.5)
    assert np.abs(sol.v[settled, 0]).max() < 1e-12
    assert np.asarray(sol.records.instants)[rest].sum() == 0


def test_every_driver_runs_the_same_split_steps():
    """simulate, integrate under jit and a batch over step sizes give the same
    trajectory and the same counts of resolved impacts."""
    ball = _ball(0.8)
    scheme = nj.DS(impact_instants=True)
    host = nj.simulate(ball.model, scheme, 0.0, 2.0, 1e-3, ball.q0, ball.v0)
    pure = jax.jit(lambda: nj.integrate(ball.model, scheme, 0.0, 2.0, 1e-3, ball.q0, ball.v0, n_steps=2000))()
    np.testing.assert_allclose(np.asarray(pure.q), host.q, rtol=0, atol=1e-13)
    impacts = len(bouncing_ball_impacts(1.0, 0.0, G, 0.8, 2.0)[0])
    assert int(pure.stats["impacts_at_instants"]) == host.stats["impacts_at_instants"] == impacts == 3
    members = simulate_batch(ball.model, scheme, 0.0, 2.0, [1e-3, 2e-3], ball.q0, ball.v0)
    np.testing.assert_allclose(members[0].q, host.q, rtol=0, atol=1e-13)
    assert [m.stats["impacts_at_instants"] for m in members] == [impacts, impacts]
    z, _ = bouncing_ball(members[1].ts, 1.0, 0.0, G, 0.8)
    assert np.abs(members[1].q[:, 0] - z).max() < 1e-9


def test_batch_of_rocking_blocks_splits_each_member_as_its_own_run():
    """A batch over step sizes of the rocking block (friction, a resting
    corner held in the path's acceleration, landings at different steps in
    each member): every member is its own run to round-off, with the same
    located landings."""
    block = load_scene("rocking_block", {})
    scheme = nj.DS(rho_inf=0.8, impact_instants=True)
    hs = [1e-3, 2e-3]
    members = simulate_batch(block.model, scheme, 0.0, 0.7, hs, block.q0, block.v0)
    p = block.parameters
    exact = rocking_impact_times(p["width"], p["height"], p["gravity"], p["tilt"], 2)  # 0.2580 s, 0.6357 s
    for h, member in zip(hs, members):
        alone = nj.simulate(block.model, scheme, 0.0, 0.7, h, block.q0, block.v0)
        np.testing.assert_allclose(member.q, alone.q, rtol=0, atol=1e-12)
        assert member.stats["failed_steps"] == alone.stats["failed_steps"] == 0
        assert member.stats["impacts_at_instants"] == alone.stats["impacts_at_instants"] == 2
        located = member.ts[np.nonzero(member.records.instants)[0]]  # the ends of the steps that hold them
        assert np.abs(located - exact).max() < 2 * h, (h, located, exact)


def test_gradient_through_the_located_instant_is_the_exact_one():
    """d z(T)/d e and d z(T)/d h0 of the ball at T = 1.2 s (after two
    bounces), by reverse mode through the split steps, equal the derivatives
    of the exact solution: the located instant moves with the parameters.
    The paper's step has no such term (its derivative in h0 is 0 here)."""
    params, build = parametrize("bouncing_ball", {"e": 0.8}, names=["e", "height"])
    T = 1.2

    def final_height(p, adjoint=nj.DiscreteAdjoint(), **options):
        model, q0, v0, _ = build(p)
        sol = nj.integrate(model, nj.DS(rho_inf=1.0, **options), 0.0, T, 1e-3, q0, v0,
                           saveat=nj.SaveAt(fn=lambda state, record: state.q[0]), adjoint=adjoint)
        return sol.records[-1]

    def exact(e, height):
        return float(np.asarray(bouncing_ball(np.array([T]), height, 0.0, G, e)[0])[0])

    d = 1e-6
    de = (exact(0.8 + d, 1.0) - exact(0.8 - d, 1.0)) / (2 * d)
    dh = (exact(0.8, 1.0 + d) - exact(0.8, 1.0 - d)) / (2 * d)
    for adjoint in (nj.DiscreteAdjoint(), nj.ImpactTimeAdjoint()):  # the event adjoint keeps the located instants'
        grad = jax.jit(jax.grad(lambda p: final_height(p, impact_instants=True, adjoint=adjoint)))(params)
        assert float(grad["e"]) == pytest.approx(de, rel=1e-7)
        assert float(grad["height"]) == pytest.approx(dh, rel=1e-7)
    paper = jax.jit(jax.grad(final_height))(params)
    assert abs(float(paper["height"])) < 1e-9 and abs(float(paper["e"]) - de) > 1.0


def test_event_adjoint_rebuilds_the_impacts_a_paper_step_takes_under_the_option():
    """With ``min_fraction`` near 1/2 no instant of the ball's bounces falls in
    the middle of its step, so every impact is the paper step's, taken
    under the option: the run is the paper's run and the event adjoint
    rebuilds each impact as it does without the option, to round-off."""
    params, build = parametrize("bouncing_ball", {"e": 0.8}, names=["e", "height"])

    def final_height(p, **options):
        model, q0, v0, _ = build(p)
        sol = nj.integrate(model, nj.DS(rho_inf=1.0, **options), 0.0, 1.2, 1e-3, q0, v0,
                           saveat=nj.SaveAt(fn=lambda state, record: (state.q[0], record.instants)),
                           adjoint=nj.ImpactTimeAdjoint())
        return sol.records[0][-1], sol.records[1]

    paper = jax.jit(jax.grad(lambda p: final_height(p)[0]))(params)
    option = dict(impact_instants=True, min_fraction=0.4999)
    located = jax.jit(lambda p: final_height(p, **option)[1])(params)
    assert int(np.sum(located)) == 0  # no impact located: each is the paper step's
    grad = jax.jit(jax.grad(lambda p: final_height(p, **option)[0]))(params)
    for name in ("e", "height"):
        assert abs(float(paper[name])) > 0.1
        assert float(grad[name]) == pytest.approx(float(paper[name]), rel=1e-10, abs=1e-12)


def test_float32_elastic_ball():
    ball = _ball(1.0)
    sol = nj.simulate(ball.model, nj.DS(rho_inf=1.0, impact_instants=True), 0.0, 5.0, 1e-3, ball.q0, ball.v0,
                      dtype="float32")
    energy = _energy(sol)
    assert sol.stats["failed_steps"] == 0 and sol.stats["impacts_at_instants"] == 6
    assert np.abs(energy / energy[0] - 1.0).max() < 1e-4


@pytest.mark.parametrize("make, match", [
    (lambda: nj.DS(impact_instants=True, max_impacts=0), r"max_impacts must be an integer >= 1, got 0"),
    (lambda: nj.DS(impact_instants=True, late=1e-3), r"late must be in \[0, 1e-06\)"),
    (lambda: nj.DS(impact_instants=True, min_fraction=0.7), r"min_fraction must be in \(0, 0.5\), got 0.7"),
    (lambda: nj.DS(impact_instants=True, short_fraction=1.0),
     r"short_fraction must be in \[0, 1\) \(a fraction of h\), got 1.0"),
    (lambda: nj.DS(impact_instants=1), r"impact_instants must be True or False, got int 1"),
])
def test_bad_settings_are_refused_by_name(make, match):
    ball = _ball(0.8)
    with pytest.raises(nj.ConfigError, match=match):
        nj.simulate(ball.model, make(), 0.0, 0.1, 1e-3, ball.q0, ball.v0)


def test_what_cannot_carry_instants_is_refused_by_name():
    with pytest.raises(nj.ConfigError, match=r"impacts = 'instants' is an option of the schemes ds, dsn; "
                                             r"scheme = 'mj'"):
        load_scene("bouncing_ball", {"scheme": "mj", "impacts": "instants"})
    assert load_scene("bouncing_ball", {"impacts": "instants"}).scheme().impact_instants
    assert not load_scene("bouncing_ball", {}).scheme().impact_instants


def test_spinning_box_rebounds_with_its_restitution():
    """Paper §4.1's box (e = 0.8, 60 rad/s spin) at h = 1e-3: its first impact
    (one vertex) rebounds with a normal rate of -e times the rate at the
    instant to within 1e-3 of e, where the paper's step is 3 % off; no other
    vertex touches, no energy is made, one impact is resolved at its instant."""
    box = load_scene("rigid_box", {"e": 0.8, "t_end": 0.45})
    observed = {}
    for name, scheme in (("instants", nj.DS(rho_inf=0.8, impact_instants=True)), ("paper", nj.DS(rho_inf=0.8))):
        sol = nj.simulate(box.model, scheme, 0.0, 0.45, 1e-3, box.q0, box.v0)
        rebound = first_rebound(box.model, sol)
        observed[name] = rebound.restitution
        assert sol.ts[0] + 0.41 < rebound.instant < 0.42  # the free flight's vertex reaches the floor at 0.4153 s
        assert sol.stats["failed_steps"] == 0
        energy = np.asarray(box.observables(sol)["energy"])
        assert energy.max() <= energy[0] * (1 + 1e-6)
        if name == "instants":
            assert sol.stats["impacts_at_instants"] == 1 and sol.stats["instant_fallbacks"] == 0
            assert rebound.rate_before < -10.0 and rebound.contact == 5
    assert abs(observed["instants"] - 0.8) < 1e-3, observed
    assert abs(observed["paper"] - 0.8) > 1e-2, observed


def test_newtons_cradle_follows_the_exact_sequence_of_collisions():
    """Five balls, gaps of 1.03 mm, e = 0.9, thrown at 1 m/s, h = 2 ms: a ball
    crosses two gaps in a step, so a step holds two collisions (the paper's
    step takes the second a step late), and at
    0.414 s two re-collisions 0.44 ms apart share a step. With the impacts
    at their instants every one of the ten collisions of the exact sequence
    in 0.5 s is located and taken in order: the centres follow the exact
    ones to 1e-9 m and the final velocities to 1e-9 m/s, where the paper's
    step is a millimetre off."""
    cradle = load_scene("newtons_cradle", {"e": 0.9, "gap": 1.03e-3})
    q0, v0 = np.asarray(cradle.q0), np.asarray(cradle.v0)
    collisions, _ = newtons_cradle_collisions(q0, v0, 0.1, 0.01, 0.9, 0.5)
    assert len(collisions) == 10 and collisions[3] - collisions[2] < 2e-3
    errors = {}
    for name, scheme in (("instants", nj.DS(rho_inf=1.0, impact_instants=True)), ("paper", nj.DS(rho_inf=1.0))):
        sol = nj.simulate(cradle.model, scheme, 0.0, 0.5, 2e-3, cradle.q0, cradle.v0, throw=False)
        x, v = newtons_cradle(np.asarray(sol.ts), q0, v0, 0.1, 0.01, 0.9)
        errors[name] = float(np.abs(np.asarray(sol.q) - x).max())
        assert sol.stats["failed_steps"] == 0
        if name == "instants":
            assert sol.stats["impacts_at_instants"] == 10 and sol.stats["instant_fallbacks"] == 0
            assert not sol.stats["warnings"], sol.stats["warnings"]  # the steps took their collisions in sequence
            np.testing.assert_allclose(np.asarray(sol.v)[-1], v[-1], atol=1e-9)
    assert errors["instants"] < 1e-9 and errors["paper"] > 1e-4, errors


def test_a_step_past_its_cap_of_instants_falls_back_and_is_counted():
    """The cradle of the test above with ``max_impacts = 1``: a step that
    resolves one collision at its instant takes what is left as one paper
    step (a fall-back), counted per step in ``records.fallback`` and in
    ``stats["instant_fallbacks"]``; where the rest of such a step held
    another collision (step 2: a ball crosses a second gap) the run warns
    by name that it resolved them at once. With the default cap (4) no
    step falls back and no warning is raised."""
    cradle = load_scene("newtons_cradle", {"e": 0.9, "gap": 1.03e-3})
    runs = {}
    for cap in (1, 4):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            runs[cap] = nj.simulate(cradle.model, nj.DS(rho_inf=1.0, impact_instants=True, max_impacts=cap),
                                    0.0, 0.5, 2e-3, cradle.q0, cradle.v0)
    capped, free = runs[1], runs[4]
    fell_back = np.asarray(capped.records.fallback)
    assert capped.stats["failed_steps"] == 0 and capped.stats["instant_fallbacks"] == int(fell_back.sum()) > 0
    assert np.all(np.asarray(capped.records.instants)[fell_back] == 1)  # the cap, then the paper's step
    assert capped.stats["impacts_at_instants"] < free.stats["impacts_at_instants"] == 10
    assert any("impacts in sequence within one step" in w and "first step 2 " in w
               for w in capped.stats["warnings"]), capped.stats["warnings"]
    assert free.stats["instant_fallbacks"] == 0 and not free.stats["warnings"]


def test_matrix_free_cube_locates_its_landing_as_the_dense_path():
    """The flexible cube (§4.4, 3 divisions, e = 0) dropped from 1 cm onto the
    floor: its 16 bottom nodes land together at the free-fall instant
    sqrt(2 · 0.01 / g) = 45.15 ms. The matrix-free path (conjugate gradients
    on element blocks, the impact's jump included) locates it as one impact,
    as the dense path does, and the two runs agree to the Krylov tolerance."""
    cube = load_scene("flexible_cube", {"divisions": 3, "height": 0.06, "e": 0.0})
    runs = {}
    for name, krylov_min_dof in (("matrix-free", 0), ("dense", None)):
        scheme = nj.DS(rho_inf=cube.scheme().rho_inf, impact_instants=True, krylov_min_dof=krylov_min_dof)
        assert scheme.matrix_free(cube.model) == (name == "matrix-free")
        sol = nj.simulate(cube.model, scheme, 0.0, 0.047, 3e-5, cube.q0, cube.v0)
        assert sol.stats["failed_steps"] == 0 and sol.stats["impacts_at_instants"] == 1, sol.stats
        landing = float(sol.ts[int(np.argmax(np.any(np.asarray(sol.records.impulse) != 0.0, axis=1)))])
        assert landing - 3e-5 < math.sqrt(2 * 0.01 / 9.81) <= landing
        runs[name] = sol
    assert np.abs(runs["matrix-free"].q - runs["dense"].q).max() < 1e-10
    assert np.abs(runs["matrix-free"].v - runs["dense"].v).max() < 1e-8


def test_first_rebound_measures_the_exact_ball():
    """metrics.first_rebound on the ball (e = 0.8, impacts at their instants:
    exact to round-off): the instant √(2 h0 / g) and the rates ∓√(2 g h0) and
    0.8 √(2 g h0); a run without an impact is refused by name."""
    ball = _ball(0.8)
    sol = nj.simulate(ball.model, nj.DS(impact_instants=True), 0.0, 0.6, 1e-3, ball.q0, ball.v0)
    rebound = first_rebound(ball.model, sol)
    speed = math.sqrt(2 * G)
    assert rebound.contact == 0
    assert rebound.instant == pytest.approx(math.sqrt(2 / G), abs=1e-9)
    assert rebound.rate_before == pytest.approx(-speed, abs=1e-8)
    assert rebound.restitution == pytest.approx(0.8, abs=1e-9)
    with pytest.raises(ValueError, match="no impact in the run"):
        first_rebound(ball.model, nj.simulate(ball.model, nj.DS(), 0.0, 0.2, 1e-3, ball.q0, ball.v0))


def test_sweep_convergence_and_identify_carry_the_option(tmp_path):
    """`nsga-jax sweep`, `convergence` and `identify` with `--set impacts=instants`:
    the swept balls (e = 0.5 and the elastic one, ρ∞ = 1) equal their exact
    solutions to 1e-9 m, which the paper's step misses by centimetres; the
    convergence study's runs agree with its reference to round-off (both
    exact); identification recovers e from synthetic bounces to 1e-10 with
    either adjoint."""
    import csv
    import json

    from nsga_jax._cli import main

    common = ["--grid", "e=0.5;1.0", "--set", "t_end=3", "--set", "rho_inf=1.0", "--h", "1e-3", "--no-plots",
              "--quiet"]
    errors = {}
    for impacts in ("instants", "end"):
        out = tmp_path / impacts
        assert main(["sweep", "bouncing_ball", *common, "--set", f"impacts={impacts}", "--out", str(out)]) == 0
        with open(out / "sweep.csv") as f:
            rows = list(csv.DictReader(f))
        errors[impacts] = [float(row["abs_error_z"]) for row in rows]
        if impacts == "instants":  # each member's located impacts, counted: the elastic ball's are exact
            counts = {float(row["e"]): int(row["impacts_at_instants"]) for row in rows}
            assert counts[1.0] == len(bouncing_ball_impacts(1.0, 0.0, G, 1.0, 3.0)[0]) and counts[0.5] > 5, rows
        else:
            assert "impacts_at_instants" not in rows[0]
    assert max(errors["instants"]) < 1e-9, errors
    assert min(errors["end"]) > 1e-3, errors
    out = tmp_path / "convergence"
    assert main(["convergence", "bouncing_ball", "--set", "impacts=instants", "--set", "t_end=0.5",
                 "--h", "2e-3,1e-3", "--ref-h", "1e-4", "--no-plots", "--out", str(out)]) == 0
    with open(out / "study.csv") as f:
        rows = list(csv.DictReader(f))
    assert rows and all(float(row["error_z"]) < 1e-10 for row in rows), rows
    assert all(row["impacts"] == "instants" and int(row["impacts_at_instants"]) > 0 for row in rows), rows
    out = tmp_path / "identify"
    identify = ["identify", "bouncing_ball", "--params", "e", "--synthetic", "--true", "e=0.7", "--initial", "e=0.5",
                "--set", "impacts=instants", "--t-end", "2", "--h", "1e-3", "--no-plots", "--out", str(out)]
    for adjoint, folder in (("discrete", out), ("event", tmp_path / "event")):
        assert main([*identify[:-1], str(folder), "--adjoint", adjoint]) == 0
        found = json.loads((folder / "identification.json").read_text())
        assert found["recovered"]["e"] == pytest.approx(0.7, abs=1e-10), (adjoint, found)


def test_hermite_path_interpolates_the_smooth_motion():
    """The cubic the look-ahead falls back on passes through (q, v) at s = 0
    and (q̃, ṽ) at s = span, and is exact for a cubic motion."""
    from nsga_jax._integrators.base import StepState
    from nsga_jax._integrators.impact_instants import hermite_path

    motion = lambda s: np.array([1.0 + 2.0 * s - 3.0 * s**2 + 0.5 * s**3, -s**3])  # noqa: E731
    rate = lambda s: np.array([2.0 - 6.0 * s + 1.5 * s**2, -3.0 * s**2])  # noqa: E731
    z = np.zeros(2)
    state = StepState(t=0.0, q=motion(0.0), v=rate(0.0), vd=z, a=z)
    path = hermite_path(state, (motion(0.7), rate(0.7)), 0.7)
    for s in (0.0, 0.2, 0.55, 0.7):
        np.testing.assert_allclose(path(s), motion(s), atol=1e-14)
    np.testing.assert_allclose(jax.jacfwd(path)(0.7), rate(0.7), atol=1e-13)


def test_energy_through_impacts_is_the_mean_over_its_window():
    ts = np.arange(0.0, 10.0, 0.5)
    energy = 2.0 + 0.1 * ts  # 2 J at the start
    impacts = np.zeros(len(ts), bool)
    assert math.isnan(energy_through_impacts(ts, energy, impacts))
    impacts[[2, 6]] = True  # the last impact at 3 s: the window (4, 6] s holds 4.5 ... 6 s
    assert energy_through_impacts(ts, energy, impacts, delay=1.0, span=2.0) == pytest.approx(
        (2.0 + 0.1 * np.mean([4.5, 5.0, 5.5, 6.0])) / 2.0 - 1.0, rel=1e-14)
    assert math.isnan(energy_through_impacts(ts, energy, impacts, delay=20.0))


def test_slider_crank_stop_keeps_the_energy_of_its_elastic_impacts():
    """The slider-crank's slider strikes its stop (e = 1, ρ∞ = 1) at 0.0412 s
    and chatters against it, pulled back by its stiff rod, four to five times
    within 0.5 ms. At h = 50 µs the Taylor path misses a re-closing the rod's
    discrete motion makes (its end leaves the slider 22 µm from the stop):
    it is located on the smooth motion's cubic instead. Every step with an
    impulse at the stop then holds a located instant, and the energy after
    the impacts (a mean after them, `metrics.energy_through_impacts`: the rod vibrates) is within 1 % of its start,
    where the paper's step loses 12 %."""
    scene = load_scene("slider_crank", {"e": 1.0})
    kept = {}
    for name, scheme in (("instants", nj.DS(rho_inf=1.0, impact_instants=True)), ("paper", nj.DS(rho_inf=1.0))):
        sol = nj.simulate(scene.model, scheme, 0.0, 0.044, 5e-5, scene.q0, scene.v0)
        energy = np.asarray(scene.observables(sol)["energy"])
        at_stop = np.asarray(sol.records.impulse)[:, -1] != 0.0
        assert sol.stats["failed_steps"] == 0 and at_stop.sum() >= 4
        kept[name] = energy_through_impacts(sol.ts, energy, at_stop, span=np.inf)
        if name == "instants":
            assert np.all(np.asarray(sol.records.instants)[at_stop] > 0), np.asarray(sol.records.instants)[at_stop]
    assert abs(kept["instants"]) < 1e-2 and kept["paper"] < -0.1, kept


@pytest.mark.slow
def test_gradient_through_instants_located_on_the_smooth_motion_matches_finite_differences():
    """The slider-crank's chatter at its stop (e = 1, h = 50 µs): one of its
    re-closings is located on the smooth motion's cubic (the Taylor path
    misses it, see the test above). Reverse mode through those split steps
    (the discrete adjoint, through the ``lax.cond`` that chooses the cubic)
    equals central differences of the same runs: the derivatives of the sum
    of the first and last coordinates at 0.0425 s in the crank's initial
    speed and the slider's mass (agreeing to 2e-5; the test allows 1e-4)."""
    params, build = parametrize("slider_crank", {"e": 1.0}, names=["crank_omega", "slider_mass"])

    def run(p):
        model, q0, v0, _ = build(p)
        return nj.integrate(model, nj.DS(rho_inf=1.0, impact_instants=True), 0.0, 0.0425, 5e-5, q0, v0,
                            saveat=nj.SaveAt(fn=lambda state, record: (state.q, record.instants, record.impulse[-1])))

    q, instants, at_stop = jax.jit(run)(params).records
    stop_steps = np.nonzero(np.asarray(at_stop))[0]
    assert len(stop_steps) >= 4 and np.all(np.asarray(instants)[stop_steps] > 0)

    def loss(p):
        q = run(p).records[0]
        return q[-1, 0] + q[-1, -1]

    grad = jax.jit(jax.grad(loss))(params)
    value = jax.jit(loss)
    for name in params:
        d = 1e-6 * float(params[name])
        up, down = dict(params), dict(params)
        up[name], down[name] = params[name] + d, params[name] - d
        fd = (float(value(up)) - float(value(down))) / (2 * d)
        assert abs(fd) > 1e-3
        assert float(grad[name]) == pytest.approx(fd, rel=1e-4), name
