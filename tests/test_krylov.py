"""Large models without assembled matrices (nsga_jax/_blocks.py,
nsga_jax/_integrators/krylov.py): the blocks and rows equal the assembled
matrices, the projected bordered solve equals the Schur-complement one, and a
run of the flexible cube on the matrix-free path equals the dense path's to
the Newton tolerance, with its gradients (both adjoints), batches and
float32; no n × n array is formed."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_blocks_equal_assembled

import nsga_jax
from nsga_jax._blocks import NodeRows
from nsga_jax._elements.hex8 import hex8_internal_force, hex8_stiffness, svk_energy
from nsga_jax._integrators.iteration_matrix import Held
from nsga_jax._integrators.krylov import KrylovConstant, KrylovFresh, KrylovHeld, KrylovOperator
from nsga_jax._integrators.linalg import Factorisation, solve_bordered
from nsga_jax._memory import dense_matrices, estimate_run_bytes
from nsga_jax.scenes import load_scene

CUBE = {"h": 3e-5, "t_end": 0.0006, "height": 0.0505, "velocity": -2.43}
"""The cube landing flat within the window: every sub-problem runs."""


def cube(divisions: int, **overrides):
    return load_scene("flexible_cube", {**CUBE, "divisions": divisions, **overrides})


def perturbed(scene, scale=1e-3, seed=0):
    rng = np.random.default_rng(seed)
    return jnp.asarray(scene.q0) + scale * jnp.asarray(rng.standard_normal(scene.model.n_dof))


def test_element_and_node_blocks_equal_the_assembled_matrices():
    scene = cube(2)
    assert_blocks_equal_assembled(scene.model, perturbed(scene))


def test_kronecker_mass_is_exact_and_preconditions_the_velocity_jump():
    scene = cube(3)
    model = scene.model
    M = model.mass(jnp.zeros(model.n_dof))
    x = jnp.asarray(np.random.default_rng(4).standard_normal(model.n_dof))
    kronecker = model.kronecker_mass()
    np.testing.assert_allclose(kronecker.mv(x), M @ x, rtol=0, atol=1e-13 * float(jnp.abs(M).max()))
    np.testing.assert_allclose(kronecker.solve(M @ x), x, rtol=0, atol=1e-13)
    np.testing.assert_allclose(kronecker.diagonal(), jnp.diagonal(M), rtol=1e-14)
    np.testing.assert_allclose(kronecker.scaled(3.0).mv(x), 3.0 * (M @ x), rtol=0, atol=1e-12 * float(jnp.abs(M).max()))
    # the velocity jump's M, solved by conjugate gradients preconditioned by the exact M⁻¹
    ops = dataclasses.replace(scene.scheme(), krylov_min_dof=0).prepare(model, 1e-4, 0.0)
    operator = ops.velocity.factored(lambda: None)
    np.testing.assert_allclose(operator.solve(M @ x), x, rtol=0, atol=1e-12)


def test_closed_form_hex8_force_and_stiffness_equal_the_energy_derivatives():
    group = cube(1).model.bodies[0].elements
    rng = np.random.default_rng(2)
    x = group.gather(jnp.asarray(cube(1).q0))[0] + 0.01 * jnp.asarray(rng.standard_normal(24))
    params = jax.tree_util.tree_map(lambda a: a[0], group.params)
    exact = -jax.jacfwd(hex8_internal_force)(x, jnp.zeros(24), params)
    np.testing.assert_allclose(hex8_stiffness(x, params), exact, rtol=0, atol=1e-13 * float(jnp.abs(exact).max()))
    np.testing.assert_allclose(hex8_stiffness(x, params), hex8_stiffness(x, params).T, rtol=0, atol=1e-15)
    # and the closed-form force is the energy's gradient
    force = hex8_internal_force(x, jnp.zeros(24), params)
    np.testing.assert_allclose(force, -jax.grad(svk_energy)(x, params), rtol=0,
                               atol=1e-13 * float(jnp.abs(force).max()))


def test_node_rows_equal_the_constraint_jacobian():
    scene = cube(3)
    model, q = scene.model, perturbed(scene)
    rows = model.constraint_rows(q)
    G = model.constraint_jacobian(q)
    assert isinstance(rows, NodeRows) and rows.shape == G.shape and rows.orthonormal()
    np.testing.assert_array_equal(rows.dense(), G)
    y = jnp.arange(G.shape[0], dtype=float) - 3.0
    np.testing.assert_allclose(rows @ q, G @ q, rtol=1e-15)
    np.testing.assert_allclose(rows.T @ y, G.T @ y, rtol=1e-15)
    np.testing.assert_allclose(abs(rows).dense(), jnp.abs(G))


def test_projected_bordered_solve_equals_the_schur_complement():
    """Orthonormal active rows eliminated by projection give solve_bordered's
    (dx, dμ), whatever the active set (the penalty's shift included)."""
    scene = cube(2)
    model, q = scene.model, perturbed(scene)
    M = model.element_mass(q).node_blocks()
    A = M.combine(1.0, model.element_stiffness(q).node_blocks(), 1e-8)
    krylov = KrylovOperator.of(A, jnp.zeros(()), jnp.zeros(()), 1e-14)
    dense = Factorisation.of(A.dense(), jnp.zeros(()), jnp.zeros(()))
    rows = model.constraint_rows(q)
    rng = np.random.default_rng(3)
    r1, r2 = jnp.asarray(rng.standard_normal(model.n_dof)), jnp.asarray(rng.standard_normal(rows.shape[0]))
    k, p = 0.7, 0.7
    for active in (np.ones(rows.shape[0], bool), rng.random(rows.shape[0]) < 0.5, np.zeros(rows.shape[0], bool)):
        active = jnp.asarray(active)
        dx, dmu = krylov.bordered(r1, r2, rows, rows, active, k, p)
        ex, emu = solve_bordered(dense, r1, r2, rows.dense(), rows.dense(), active, k, p)
        np.testing.assert_allclose(dx, ex, rtol=0, atol=1e-10 * float(jnp.abs(ex).max()))
        np.testing.assert_allclose(dmu, emu, rtol=0, atol=1e-10 * float(jnp.abs(emu).max()))


def test_the_switch_follows_the_model_structure_and_size():
    model = cube(3).model
    ds = nsga_jax.DS()
    assert model.matrix_free and "matrix_free" in nsga_jax.check_model(model, jnp.asarray(cube(3).q0))
    # the measured switch: the paper's cube (648) is solved matrix-free, 4 divisions (375) dense
    assert ds.matrix_free(cube(5).model) and not ds.matrix_free(cube(4).model)
    kinds = dataclasses.replace(ds, krylov_min_dof=0).matrix_kinds(model)
    assert kinds == (KrylovHeld, KrylovHeld, KrylovConstant)  # the velocity jump's M + h C, C = 0, is constant
    kinds = dataclasses.replace(ds, krylov_min_dof=0, reuse_min_dof=10**9).matrix_kinds(model)
    assert kinds == (KrylovFresh, KrylovFresh, KrylovConstant)
    assert dataclasses.replace(ds, krylov_min_dof=model.n_dof + 1).matrix_kinds(model) == (Held,) * 3
    assert dataclasses.replace(ds, krylov_min_dof=0, fast_paths=False).matrix_kinds(model)[0] is not KrylovFresh
    dsn = dataclasses.replace(nsga_jax.DSn(), krylov_min_dof=0)
    assert dsn.matrix_kinds(model) == (KrylovHeld, KrylovConstant, KrylovConstant)  # S_t^p = M without h² K
    # friction too (tests/test_matrix_free_systems.py); other scenes never (the bar is:
    # test_bar_matches_its_tridiagonal_path)
    assert cube(3, mu=0.3).model.matrix_free
    for name in ("bouncing_ball", "rigid_box", "flexible_pendulum"):
        assert not load_scene(name).model.matrix_free, name
    assert dense_matrices(model, dataclasses.replace(ds, krylov_min_dof=0)) == 0


def run_both(scene, scheme, dtype="float64", **kwargs):
    args = (0.0, scene.solver["t_end"], scene.solver["h"], scene.q0, scene.v0)
    krylov = nsga_jax.simulate(scene.model, dataclasses.replace(scheme, krylov_min_dof=0), *args, dtype=dtype, **kwargs)
    dense = nsga_jax.simulate(scene.model, dataclasses.replace(scheme, krylov_min_dof=None), *args, **kwargs)
    return krylov, dense


def assert_same_run(krylov, dense, atol):
    assert krylov.n_steps == dense.n_steps and krylov.failed_steps.size == 0 and dense.failed_steps.size == 0
    scale = float(np.abs(dense.q).max())
    np.testing.assert_allclose(krylov.q, dense.q, rtol=0, atol=atol * scale)
    np.testing.assert_array_equal(krylov.records.active_velocity, dense.records.active_velocity)
    assert np.asarray(dense.records.active_velocity).any()  # the landing is in the window


def test_cube_matches_the_dense_path_at_the_default_tolerance():
    """Both paths end on iterates that pass eq. 51; they differ by a few
    tolerances (tol_r = 1e-8 by default, positions of order 0.1 m)."""
    scene = cube(2)
    scheme = scene.scheme()
    krylov, dense = run_both(scene, scheme)
    assert_same_run(krylov, dense, atol=10 * float(scheme.tol_r))


def test_cube_warm_started_on_the_matrix_free_path_is_the_same_run():
    """Newton from the last step's multipliers (``warm_start``) on the
    Krylov path: the landing cube's run equals the zero-started one to a few
    tolerances, with the same contacts active, in no more iterations (its
    sub-problems converge in one iteration from either start)."""
    scene = cube(2)
    scheme = dataclasses.replace(scene.scheme(), krylov_min_dof=0)
    assert scheme.matrix_free(scene.model)
    args = (0.0, scene.solver["t_end"], scene.solver["h"], scene.q0, scene.v0)
    cold = nsga_jax.simulate(scene.model, scheme, *args)
    warm = nsga_jax.simulate(scene.model, dataclasses.replace(scheme, warm_start=True), *args)
    assert_same_run(warm, cold, atol=10 * float(scheme.tol_r))
    for sub in ("position", "velocity"):
        assert warm.stats["iterations"][sub]["mean"] <= cold.stats["iterations"][sub]["mean"], sub


def test_bar_matches_its_tridiagonal_path():
    """The bar on node blocks of width 1 with the diagonal preconditioner
    (no Kronecker mass) against its block elimination, through the impact;
    a chain stays on its band by default, however long."""
    scene = load_scene("impacting_bar", {"gap": 0.01, "h": 1e-3, "t_end": 0.05})
    scheme = scene.scheme()
    model = scene.model
    assert model.matrix_free and model.kronecker_mass() is None
    assert dataclasses.replace(scheme, krylov_min_dof=0).matrix_kinds(model) == (KrylovConstant,) * 3
    long_bar = load_scene("impacting_bar", {"n_elements": 2000}).model
    assert not scheme.matrix_free(long_bar) and scheme.matrix_kinds(long_bar)[0].__name__ == "ConstantTridiagonal"
    krylov, dense = run_both(scene, scheme)
    assert_same_run(krylov, dense, atol=10 * float(scheme.tol_r))
    np.testing.assert_allclose(krylov.v, dense.v, rtol=0, atol=10 * float(scheme.tol_r) * float(np.abs(dense.v).max()))


@pytest.mark.slow
@pytest.mark.parametrize("scheme", ["ds", "dsn"])
def test_cube_matches_the_dense_path_at_a_tight_tolerance(scheme):
    scene = cube(3, scheme=scheme)
    krylov, dense = run_both(scene, dataclasses.replace(scene.scheme(), tol_r=1e-10, tol_f=1e-10))
    assert_same_run(krylov, dense, atol=1e-8)
    np.testing.assert_allclose(krylov.v, dense.v, rtol=0, atol=1e-7 * float(np.abs(dense.v).max()))


@pytest.mark.slow
def test_float32_run_matches_float64_dense():
    scene = cube(2)
    krylov, dense = run_both(scene, scene.scheme(), dtype="float32")
    assert krylov.q.dtype == np.float32
    assert_same_run(krylov, dense, atol=1e-4)


def landing_loss(scheme, adjoint, steps=8):
    """The mean square vertical velocity of the nodes after the landing, as a function of (E, v0)."""
    from nsga_jax.scenes import parametrize

    params, build = parametrize("flexible_cube", {**CUBE, "divisions": 2}, ["E", "velocity"])

    def loss(p):
        model, q0, v0, _ = build(p)
        h = CUBE["h"]
        sol = nsga_jax.integrate(model, scheme, 0.0, steps * h, h, q0, v0, n_steps=steps, adjoint=adjoint)
        return jnp.mean(sol.v[-1].reshape(-1, 3)[:, 2] ** 2)

    return params, loss


@pytest.mark.slow
@pytest.mark.parametrize("scheme_class, adjoint", [
    (nsga_jax.DS, nsga_jax.DiscreteAdjoint()), (nsga_jax.DS, nsga_jax.ImpactTimeAdjoint()),
    (nsga_jax.DSn, nsga_jax.ImpactTimeAdjoint())], ids=["discrete", "impact_time", "dsn-impact_time"])
def test_gradients_through_the_landing_match_the_dense_path(scheme_class, adjoint):
    ds = scheme_class(tol_r=1e-10, tol_f=1e-10)
    grads = {}
    for name, scheme in (("krylov", dataclasses.replace(ds, krylov_min_dof=0)), ("dense", ds)):
        params, loss = landing_loss(scheme, adjoint)
        grads[name] = jax.jit(jax.grad(loss))(params)
        forward = jax.jit(jax.jacfwd(loss))(params)
        for k in params:
            np.testing.assert_allclose(float(grads[name][k]), float(forward[k]), rtol=1e-9, err_msg=f"{name} {k}")
    for k in grads["dense"]:
        assert abs(float(grads["dense"][k])) > 1e-8, f"{k}: zero gradient proves nothing"
        np.testing.assert_allclose(float(grads["krylov"][k]), float(grads["dense"][k]), rtol=1e-6, err_msg=k)


@pytest.mark.slow
def test_a_batch_equals_its_single_runs():
    scheme = dataclasses.replace(nsga_jax.DS(), krylov_min_dof=0)
    params, loss = landing_loss(scheme, nsga_jax.DiscreteAdjoint(), steps=6)
    batch = {"E": jnp.asarray([80.0, 100.0]), "velocity": jnp.asarray([-2.0, -3.0])}
    batched = jax.jit(jax.vmap(loss))(batch)
    grads = jax.jit(jax.vmap(jax.grad(loss)))(batch)
    for i in range(2):
        member = {k: v[i] for k, v in batch.items()}
        np.testing.assert_allclose(float(batched[i]), float(loss(member)), rtol=1e-12)
        single = jax.jit(jax.grad(loss))(member)
        for k in params:
            np.testing.assert_allclose(float(grads[k][i]), float(single[k]), rtol=1e-9, err_msg=f"{k}[{i}]")


def test_no_n_by_n_array_is_formed():
    """The jaxpr of a step, of the run's preparation and of its start holds no
    array with two axes as long as n (the dense path's has several)."""
    scene = cube(6)  # n = 1,029
    model, n = scene.model, scene.model.n_dof
    q0, v0 = jnp.asarray(scene.q0), jnp.asarray(scene.v0)

    def largest(scheme):
        h = scene.solver["h"]
        ops = scheme.prepare(model, h, 0.0)
        state = scheme.init(model, 0.0, q0, v0)
        shapes = []
        for fn, args in ((lambda s: scheme.step(model, ops, s, h), (state,)),
                         (lambda t: scheme.prepare(model, h, t), (0.0,)),
                         (lambda q: scheme.init(model, 0.0, q, v0), (q0,))):
            jaxpr = jax.make_jaxpr(fn)(*args)
            shapes += [v.aval.shape for eqn in _equations(jaxpr.jaxpr) for v in eqn.outvars]
            shapes += [np.shape(c) for c in jaxpr.consts]
        return max(sum(1 for d in s if d >= n) for s in shapes)

    assert largest(dataclasses.replace(scene.scheme(), krylov_min_dof=0)) <= 1
    assert largest(dataclasses.replace(scene.scheme(), krylov_min_dof=None)) == 2
    assert scene.scheme().matrix_kinds(model)[0] is KrylovHeld  # 1,029 coordinates: matrix-free by default


def _equations(jaxpr):
    for eqn in jaxpr.eqns:
        yield eqn
        for param in eqn.params.values():
            for inner in (param if isinstance(param, (tuple, list)) else (param,)):
                inner = getattr(inner, "jaxpr", inner)
                if hasattr(inner, "eqns"):
                    yield from _equations(inner)


def test_memory_estimate_of_the_matrix_free_path_is_linear():
    ds = dataclasses.replace(nsga_jax.DS(), krylov_min_dof=0)
    small, large = (estimate_run_bytes(load_scene("flexible_cube", {"divisions": d}).model, ds) for d in (10, 40))
    assert small.dense == large.dense == 0 and small.blocks_bytes > 0
    ratio = large.blocks_bytes / small.blocks_bytes
    n_ratio = large.n_dof / small.n_dof
    assert 0.8 * n_ratio < ratio < 1.5 * n_ratio  # linear in n
    assert large.needed < 10e9  # 206,763 coordinates in a few GB (the dense path: thousands)
    dense = estimate_run_bytes(load_scene("flexible_cube", {"divisions": 40}).model, nsga_jax.DS(krylov_min_dof=None))
    assert dense.needed > 100 * large.needed


def test_a_large_cube_that_cannot_fit_is_refused_naming_the_matrix_free_path(tmp_path, capsys, monkeypatch):
    from nsga_jax import _memory as memory
    from nsga_jax._cli import main

    monkeypatch.delenv(memory.SKIP_ENV, raising=False)
    monkeypatch.setattr(memory, "available_memory", lambda: 0.5e9)
    code = main(["run", "flexible_cube", "--set", "divisions=40", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code != 0 and err[-1].startswith("error: ")
    assert "206,763 coordinates (element blocks and vectors, no matrix assembled" in err[-1]


@pytest.mark.slow
def test_a_sweep_of_a_large_cube_equals_its_single_runs(tmp_path):
    """A sweep batches members on the matrix-free path (1,536 coordinates:
    matrix-free by default) and gives each member's single run."""
    from nsga_jax._sweep import sweep

    overrides = {**CUBE, "divisions": 7, "t_end": 12 * CUBE["h"]}
    result = sweep("flexible_cube", {"E": [80.0, 100.0]}, overrides=overrides, out=tmp_path / "s")
    assert load_scene("flexible_cube", overrides).scheme().matrix_kinds(cube(7).model)[0] is KrylovHeld
    for row in result.rows:
        single = load_scene("flexible_cube", {**overrides, "E": row["E"]}).run()
        observed = single.observables
        assert row["failed_steps"] == 0 and single.failed_steps.size == 0
        for name in ("x8_uz", "x8_vz", "x1_uz", "energy"):
            scale = float(np.abs(observed[name]).max())
            np.testing.assert_allclose(row[f"{name}_final"], observed[name][-1], rtol=0, atol=1e-12 * scale,
                                       err_msg=name)
