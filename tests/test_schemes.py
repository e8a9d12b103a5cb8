"""DSn, CS and Moreau-Jean beside DS: the paper's qualitative claims, fast versions."""

import numpy as np
import pytest
from reference_models import BouncingBall

import nsga_jax as nj
from nsga_jax.scenes import load_scene


@pytest.fixture(scope="module")
def bar_h002():
    return {s: load_scene("impacting_bar", {"h": 0.02, "scheme": s}).run(throw=False) for s in ("ds", "dsn", "cs")}


def test_ds_needs_one_iteration_per_subproblem_at_large_step(bar_h002):
    ds = bar_h002["ds"]
    assert ds.stats["failed_steps"] == 0
    assert ds.iterations.max() == 1


def test_cs_fails_or_needs_far_more_solves_on_the_bar(bar_h002):
    ds, cs = bar_h002["ds"], bar_h002["cs"]
    # default cap: 50 global iterations (150 linear solves) per step
    failed = cs.stats["failed_steps"] > 0
    solves = {s: sol.stats["iterations"]["linear_solves"]["max"] for s, sol in (("ds", ds), ("cs", cs))}
    assert failed or solves["cs"] >= 10 * solves["ds"]
    if failed:
        assert cs.result in (nj.Result.coupled_max_iter, nj.Result.coupled_diverged)


def test_dsn_rebound_differs_from_ds(bar_h002):
    ds, dsn = bar_h002["ds"], bar_h002["dsn"]
    assert dsn.stats["failed_steps"] == 0
    # rigid-body velocity at the end: DS bounces back at about -v0, DSn does not reproduce it
    v_ds, v_dsn = ds.v[-1].mean(), dsn.v[-1].mean()
    assert v_ds == pytest.approx(-10.0, rel=0.1)
    assert abs(v_dsn - v_ds) > 1.0


def test_cs_agrees_with_ds_at_small_step():
    ds = load_scene("impacting_bar", {"h": 1e-3, "scheme": "ds"}).run()
    cs = load_scene("impacting_bar", {"h": 1e-3, "scheme": "cs", "max_iter": 200}).run()
    # same first-order accuracy: the tip histories agree to O(h)
    assert np.abs(ds.observables["tip_u"] - cs.observables["tip_u"]).max() < 0.05
    assert cs.stats["iterations"]["linear_solves"]["mean"] > ds.stats["iterations"]["linear_solves"]["mean"]


def test_dsn_equals_ds_without_nonsmooth_forces():
    # the ball's force is constant: f^p = f* = 0, so DSn is DS exactly
    ds = load_scene("bouncing_ball", {"scheme": "ds", "t_end": 2.0}).run()
    dsn = load_scene("bouncing_ball", {"scheme": "dsn", "t_end": 2.0}).run()
    np.testing.assert_array_equal(ds.q, dsn.q)


def test_moreau_jean_drifts_where_ds_does_not():
    runs = {s: load_scene("rigid_pendulum", {"scheme": s, "t_end": 10.0}).run() for s in ("ds", "mj")}
    runs["mj1"] = load_scene("rigid_pendulum", {"scheme": "mj", "theta": 1.0, "t_end": 10.0}).run()
    for sol in runs.values():
        assert sol.stats["failed_steps"] == 0
    drift = {s: np.abs(sol.observables["constraint"]) for s, sol in runs.items()}
    assert drift["ds"].max() < 1e-8
    # Moreau-Jean keeps the rod at velocity level only. With theta = 1 the length
    # error grows with time (|q_{n+1}|² = |q_n|² - h² |v_{n+1}|² per step) ...
    early, late = drift["mj1"][:1000].max(), drift["mj1"][-1000:].max()
    assert late > 2 * early and late > 1e-3
    # ... with theta = 1/2 it stays bounded (the step error h²/4 (|v_n|² - |v_{n+1}|²)
    # telescopes) but far above DS's
    assert 1e-7 < drift["mj"].max() < 1e-4


def test_moreau_jean_impact_law_and_theta():
    e = 0.5
    sol = load_scene("bouncing_ball", {"scheme": "mj", "e": e, "t_end": 1.0}).run()
    k = np.nonzero(sol.impulse[:, 0] > 0)[0][0]
    assert sol.v[k, 0] == pytest.approx(-e * sol.v[k - 1, 0], rel=1e-10)
    with pytest.raises(nj.ConfigError, match=r"theta must be in \[0, 1\]"):
        load_scene("bouncing_ball", {"scheme": "mj", "theta": 1.5})
    with pytest.raises(nj.ConfigError, match=r"theta must be in \[0, 1\]"):
        nj.simulate(BouncingBall(m=1.0, gravity=9.81, e=0.5), nj.MJ(theta=-0.1), 0.0, 1.0, 1e-3, [1.0], [0.0])


def test_cs_reports_divergence_or_cap_with_a_named_error():
    with pytest.raises(nj.ConvergenceError, match="coupled") as info:
        load_scene("impacting_bar", {"h": 0.02, "scheme": "cs"}).run()
    assert info.value.result in (nj.Result.coupled_max_iter, nj.Result.coupled_diverged)
    assert np.all(np.isfinite(info.value.solution.q))  # reported, not propagated as NaNs


def test_scheme_names_are_one_list():
    """Configs, the command line and nj.SCHEMES name the schemes from one list,
    and each class carries its own name."""
    from nsga_jax._integrators import scheme_class
    from nsga_jax._scenes.params import SOLVER_PARAMS
    from nsga_jax._validation import SCHEME_NAMES

    assert tuple(nj.SCHEMES) == SCHEME_NAMES == SOLVER_PARAMS["scheme"].choices
    assert all(scheme_class(name).name == name and nj.SCHEMES[name] is scheme_class(name) for name in SCHEME_NAMES)
