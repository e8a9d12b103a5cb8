"""The matrix-free path (nsga_jax/_system/matrix_free.py,
nsga_jax/_integrators/krylov.py) on systems of several flexible bodies and
with joints and friction: the stacked element blocks and the rows (pins' and contacts')
equal the assembled matrices and the constraint Jacobian, the switch follows
the parts, and two cubes landing on a floor and a clamped beam whose tip
falls onto a floor, and a cube landing while sliding with Coulomb friction,
run as on the dense path, to the Newton tolerance, with
the same contacts closing, the pins held, and the same gradients."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import assert_blocks_equal_assembled

import nsga_jax
from nsga_jax._integrators.krylov import KRYLOV_KINDS
from nsga_jax.system import Distance, Gravity, HexSolid, Pin, PlaneContact, RigidBody3D, System

SIDE, E, NU, RHO = 0.1, 90.0, 0.3, 1.0  # the flexible_cube scene's soft cube


def two_cubes(rigid: bool = False):
    """Two 2 × 2 × 2 cubes side by side, about to land on a floor (the first
    at 1 mm above it, the second at 1.5 mm, falling at 2.4 and 1.2 m/s)."""
    system = System(dim=3)
    for name, x, height, speed in (("left", -0.1, 0.051, -2.4), ("right", 0.1, 0.0515, -1.2)):
        cube = HexSolid(size=jnp.full((3,), SIDE), divisions=(2, 2, 2), E=E, nu=NU, rho=RHO,
                        position=jnp.array([x, 0.0, height]), velocity=jnp.array([0.0, 0.0, speed]))
        system.add_body(name, cube)
        system.add_contact(f"{name}_floor", PlaneContact(name, normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, 0.0],
                                                          e=0.0, nodes="bottom"))
    system.add_force("gravity", Gravity(jnp.array([0.0, 0.0, -9.81])))
    if rigid:
        system.add_body("block", RigidBody3D(mass=1.0, inertia=jnp.eye(3), position=jnp.array([0.0, 0.5, 1.0])))
    return system.model()


def test_stacked_blocks_and_rows_equal_the_assembled_matrices():
    model = two_cubes()
    assert model.matrix_free
    q0, _ = model.initial_state()
    q = q0 + 1e-3 * jnp.asarray(np.random.default_rng(0).standard_normal(model.n_dof))
    assert_blocks_equal_assembled(model, q)
    rows = model.constraint_rows(q)
    assert rows.orthonormal() and rows.shape == (18, model.n_dof)
    np.testing.assert_allclose(rows.dense(), model.constraint_jacobian(q), rtol=0, atol=1e-15)
    nsga_jax.check_model(model)  # the declared capabilities, matrix_free among them, hold


def test_a_rigid_body_beside_them_keeps_the_dense_path():
    """A rigid body has no element blocks (and rigidity rows): the system is not matrix-free."""
    assert not two_cubes(rigid=True).matrix_free


def test_two_cubes_landing_match_the_dense_path():
    model = two_cubes()
    q0, v0 = model.initial_state()
    scheme = nsga_jax.DS()
    kinds = dataclasses.replace(scheme, krylov_min_dof=0).matrix_kinds(model)
    assert all(issubclass(kind, KRYLOV_KINDS) for kind in kinds)
    runs = [nsga_jax.simulate(model, dataclasses.replace(scheme, krylov_min_dof=k), 0.0, 0.0015, 3e-5, q0, v0)
            for k in (0, None)]
    krylov, dense = runs
    assert krylov.n_steps == dense.n_steps == 50
    assert krylov.failed_steps.size == 0 and dense.failed_steps.size == 0
    np.testing.assert_allclose(krylov.q, dense.q, rtol=0, atol=10 * float(scheme.tol_r) * float(np.abs(dense.q).max()))
    closed = np.asarray(dense.records.active_velocity)
    np.testing.assert_array_equal(np.asarray(krylov.records.active_velocity), closed)
    assert closed[:, :9].any() and closed[:, 9:].any()  # both cubes land within the window


def clamped_beam(E=1e4, distance: bool = False):
    """A 0.3 m beam of six hexahedra clamped at x = 0 (each node of its left
    face pinned to the ground) and sagging under gravity, its tip's lower
    edge 0.5 mm above a floor; ``distance``: one clamp a rod instead (not
    affine: the dense path)."""
    beam = HexSolid(size=jnp.array([0.3, 0.05, 0.05]), divisions=(6, 1, 1), E=E, nu=0.3, rho=1000.0,
                    position=jnp.array([0.15, 0.0, 0.0255]))
    system = System(dim=3)
    system.add_body("beam", beam)
    reference = beam.reference_nodes
    for i, node in enumerate(beam.node_set("left")):
        system.add_joint(f"clamp_{i}", Pin("ground", "beam", at_a=reference[node], node_b=node))
    if distance:
        system.add_joint("rod", Distance("ground", "beam", at_a=[0.3, 0.0, 1.0], node_b=beam.node(-1, 0, -1),
                                         length=1.0 - 0.0505))
    tip = (beam.node(-1, 0, 0), beam.node(-1, -1, 0))
    system.add_contact("floor", PlaneContact("beam", normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, 0.0], e=0.0, nodes=tip))
    system.add_force("gravity", Gravity(jnp.array([0.0, 0.0, -9.81])))
    return system.model()


def test_pinned_nodes_rows_are_the_coordinate_axes():
    model = clamped_beam()
    assert model.matrix_free and model.n_bilateral == 12
    q0, _ = model.initial_state()
    rows = model.constraint_rows(q0)
    assert rows.orthonormal() and rows.shape == (14, model.n_dof)
    np.testing.assert_allclose(rows.dense(), model.constraint_jacobian(q0), rtol=0, atol=1e-15)
    nsga_jax.check_model(model)
    assert not clamped_beam(distance=True).matrix_free  # a rod's row is not affine


def test_a_pinned_node_in_a_contact_keeps_the_dense_path():
    """A node pinned and in a contact: its rows would not be orthonormal."""
    beam = HexSolid(size=jnp.full((3,), 0.1), divisions=(1, 1, 1), E=E, nu=NU, rho=RHO)
    system = System(dim=3)
    system.add_body("cube", beam)
    system.add_joint("pin", Pin("ground", "cube", at_a=np.asarray(beam.reference_nodes)[0], node_b=0))
    system.add_contact("floor", PlaneContact("cube", normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, -0.1], e=0.0,
                                                nodes="bottom"))
    assert not system.model().matrix_free


@pytest.mark.parametrize("scheme", [nsga_jax.DS(), pytest.param(nsga_jax.DSn(), marks=pytest.mark.slow)],
                         ids=["ds", "dsn"])
def test_clamped_beam_matches_the_dense_path(scheme):
    """The tip falls onto the floor and stays (e = 0); the clamp holds to
    round-off on both paths, whose trajectories agree to the Newton tolerance."""
    model = clamped_beam()
    q0, v0 = model.initial_state()
    kinds = dataclasses.replace(scheme, krylov_min_dof=0).matrix_kinds(model)
    assert all(issubclass(kind, KRYLOV_KINDS) for kind in kinds)
    krylov, dense = [nsga_jax.simulate(model, dataclasses.replace(scheme, krylov_min_dof=k), 0.0, 0.03, 2e-4, q0, v0)
                     for k in (0, None)]
    assert krylov.failed_steps.size == 0 and dense.failed_steps.size == 0
    scale = float(np.abs(dense.q).max())
    np.testing.assert_allclose(krylov.q, dense.q, rtol=0, atol=10 * float(scheme.tol_r) * scale)
    closed = np.asarray(dense.records.active_velocity)[:, 12:]
    np.testing.assert_array_equal(np.asarray(krylov.records.active_velocity)[:, 12:], closed)
    assert closed.any(axis=0).all() and closed[-1].all()  # the tip's edge lands and stays
    clamped = np.concatenate([np.arange(3 * n, 3 * n + 3) for n in (0, 7, 14, 21)])  # the left face's nodes
    assert np.abs(krylov.q[:, clamped] - q0[clamped]).max() < 1e-12
    assert np.abs(krylov.q[-1] - q0).max() > 4e-3  # the beam has sagged onto the floor


@pytest.mark.slow
def test_gradient_through_the_clamped_beam_matches_the_dense_path():
    """d/dE of a node's final height near the clamp (where the clamp's
    bending wave has reached in 10 ms), both paths, against central differences."""
    scheme = nsga_jax.DS(tol_r=1e-10, tol_f=1e-10)
    node = 3 * 1 + 2  # z of node (1, 0, 0), 5 cm from the clamp

    def height(E, k):
        model = clamped_beam(E)
        q0, v0 = model.initial_state()
        sol = nsga_jax.integrate(model, dataclasses.replace(scheme, krylov_min_dof=k), 0.0, 0.01, 2e-4, q0, v0,
                                 n_steps=50)
        return sol.q[-1, node]

    grads = {k: float(jax.jit(jax.grad(lambda E: height(E, k)))(1e4)) for k in (0, None)}
    step = 10.0
    fd = (float(height(1e4 + step, 0)) - float(height(1e4 - step, 0))) / (2 * step)
    assert abs(grads[None]) * 1e4 > 1e-5  # E dz/dE [m]: far above the Newton tolerance
    np.testing.assert_allclose(grads[0], grads[None], rtol=1e-6)
    np.testing.assert_allclose(grads[0], fd, rtol=1e-4)


def sliding_cube(mu=0.3, **overrides):
    from nsga_jax.scenes import load_scene

    return load_scene("flexible_cube", {"h": 3e-5, "t_end": 0.0009, "height": 0.0505, "velocity": -2.43,
                                        "divisions": 2, "mu": mu, "vx": 0.5, **overrides})


def test_cube_landing_with_friction_matches_the_dense_path():
    """The cube lands while sliding (vx = 0.5 m/s, μ = 0.3): its nine
    frictional contacts close, friction slows it, and both paths agree to the
    Newton tolerance."""
    scene = sliding_cube()
    model, scheme = scene.model, scene.scheme()
    assert model.matrix_free and model.n_friction == 9
    nsga_jax.check_model(model)
    kinds = dataclasses.replace(scheme, krylov_min_dof=0).matrix_kinds(model)
    assert all(issubclass(kind, KRYLOV_KINDS) for kind in kinds)
    args = (0.0, scene.solver["t_end"], scene.solver["h"], scene.q0, scene.v0)
    krylov, dense = [nsga_jax.simulate(model, dataclasses.replace(scheme, krylov_min_dof=k), *args) for k in (0, None)]
    assert krylov.failed_steps.size == 0 and dense.failed_steps.size == 0
    scale = float(np.abs(dense.q).max())
    np.testing.assert_allclose(krylov.q, dense.q, rtol=0, atol=10 * float(scheme.tol_r) * scale)
    np.testing.assert_allclose(krylov.v, dense.v, rtol=0, atol=1e-6)
    closed = np.asarray(dense.records.active_velocity)
    np.testing.assert_array_equal(np.asarray(krylov.records.active_velocity), closed)
    assert closed.any(axis=0).all()
    vx = krylov.v[-1].reshape(-1, 3)[:, 0].mean()
    assert vx < 0.45  # friction has slowed the slide (0.5 m/s at the landing)


@pytest.mark.slow
def test_gradient_through_the_sliding_landing_matches_the_dense_path():
    """d/dμ of the cube's final mean horizontal velocity, both paths, against central differences."""
    from nsga_jax.scenes import parametrize

    base = {"h": 3e-5, "t_end": 0.0006, "height": 0.0505, "velocity": -2.43, "divisions": 2, "mu": 0.3, "vx": 0.5}
    params, build = parametrize("flexible_cube", base, ["mu"])
    scheme = nsga_jax.DS(tol_r=1e-10, tol_f=1e-10)

    def speed(p, k):
        model, q0, v0, _ = build(p)
        sol = nsga_jax.integrate(model, dataclasses.replace(scheme, krylov_min_dof=k), 0.0, 0.0006, 3e-5, q0, v0,
                                 n_steps=20)
        return jnp.mean(sol.v[-1].reshape(-1, 3)[:, 0])

    grads = {k: float(jax.jit(jax.grad(lambda p: speed(p, k)))(params)["mu"]) for k in (0, None)}
    step = 1e-4
    fd = (float(speed({"mu": params["mu"] + step}, 0)) - float(speed({"mu": params["mu"] - step}, 0))) / (2 * step)
    assert grads[None] < -1e-3  # more friction, slower
    np.testing.assert_allclose(grads[0], grads[None], rtol=1e-6)
    np.testing.assert_allclose(grads[0], fd, rtol=1e-4)


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["dsn", "impact_instants", "warm_start", "energetic"])
def test_sliding_landing_with_each_option_matches_the_dense_path(variant):
    """Friction on the matrix-free path with DSn, impacts at their instants,
    warm starts and the energetic impact law: the dense path's run each time."""
    scene = sliding_cube()
    base = scene.scheme()
    scheme = {"dsn": dataclasses.replace(nsga_jax.DSn(), tol_r=base.tol_r),
              "impact_instants": dataclasses.replace(base, impact_instants=True),
              "warm_start": dataclasses.replace(base, warm_start=True),
              "energetic": dataclasses.replace(base, impact_law="energetic")}[variant]
    args = (0.0, scene.solver["t_end"], scene.solver["h"], scene.q0, scene.v0)
    krylov, dense = [nsga_jax.simulate(scene.model, dataclasses.replace(scheme, krylov_min_dof=k), *args)
                     for k in (0, None)]
    assert krylov.failed_steps.size == 0 and dense.failed_steps.size == 0
    np.testing.assert_allclose(krylov.q, dense.q, rtol=0, atol=10 * float(scheme.tol_r) * float(np.abs(dense.q).max()))
    np.testing.assert_allclose(krylov.v, dense.v, rtol=0, atol=1e-6)


@pytest.mark.slow
def test_a_batch_with_friction_equals_its_single_runs():
    scene = sliding_cube(t_end=0.0006)
    scheme = dataclasses.replace(scene.scheme(), krylov_min_dof=0)
    batch = nsga_jax.simulate_batch(scene.model, scheme, 0.0, 0.0006, [3e-5, 4.5e-5], scene.q0, scene.v0)
    for h, member in zip((3e-5, 4.5e-5), batch):
        single = nsga_jax.simulate(scene.model, scheme, 0.0, 0.0006, h, scene.q0, scene.v0)
        assert member.failed_steps.size == 0
        np.testing.assert_allclose(member.q, single.q, rtol=0, atol=1e-12)


CASES = [("mj", "sliding"), ("cs", "landing")] + [
    pytest.param(scheme, case, marks=pytest.mark.slow)
    for scheme, case in [("mj", "landing"), ("mj", "clamped"), ("mj", "two_cubes"), ("cs", "clamped"),
                         ("cs", "two_cubes")]]


@pytest.mark.parametrize("scheme_name, case", CASES)
def test_cs_and_mj_on_the_matrix_free_path_match_their_dense_paths(scheme_name, case):
    """MJ's one iteration matrix M + (hθ)² K and CS's three diagonal blocks
    as element blocks: the sliding cube with friction (MJ), the frictionless
    landing, the clamped beam and two cubes run as each scheme's dense path
    does, to its Newton tolerance. (CS fails the sliding cube's steps on both
    paths alike: its coupled iteration, docs/combinations.md.)"""
    if case in ("sliding", "landing"):
        scene = sliding_cube(mu=0.3 if case == "sliding" else 0.0)
        model, q0, v0, t_end, h = scene.model, scene.q0, scene.v0, scene.solver["t_end"], scene.solver["h"]
    else:
        model = clamped_beam() if case == "clamped" else two_cubes()
        (q0, v0), t_end, h = model.initial_state(), (0.03 if case == "clamped" else 0.0015), (
            2e-4 if case == "clamped" else 3e-5)
    scheme = nsga_jax.MJ() if scheme_name == "mj" else nsga_jax.CS(tol_r=1e-8)
    kinds = dataclasses.replace(scheme, krylov_min_dof=0).matrix_kinds(model)
    assert all(issubclass(kind, KRYLOV_KINDS) for kind in kinds if kind.__name__ != "Refactored")  # present ones
    assert any(issubclass(kind, KRYLOV_KINDS) for kind in kinds)
    krylov, dense = [nsga_jax.simulate(model, dataclasses.replace(scheme, krylov_min_dof=k), 0.0, t_end, h, q0, v0)
                     for k in (0, None)]
    assert krylov.failed_steps.size == 0 and dense.failed_steps.size == 0
    np.testing.assert_allclose(krylov.q, dense.q, rtol=0,
                               atol=10 * float(scheme.tol_r) * float(np.abs(dense.q).max()))
    np.testing.assert_allclose(krylov.v, dense.v, rtol=0, atol=1e-5)
    closed = np.asarray(dense.records.active_velocity)
    np.testing.assert_array_equal(np.asarray(krylov.records.active_velocity), closed)
    assert closed.any()


@pytest.mark.slow
def test_moreau_jean_gradient_on_the_matrix_free_path_matches_its_dense_path():
    """d/dμ and d/dE of the sliding cube's final velocities with MJ, both paths (CS has no adjoint)."""
    from nsga_jax.scenes import parametrize

    base = {"h": 3e-5, "t_end": 0.0006, "height": 0.0505, "velocity": -2.43, "divisions": 2, "mu": 0.3, "vx": 0.5}
    params, build = parametrize("flexible_cube", base, ["mu", "E"])
    mj = nsga_jax.MJ(tol_r=1e-10, tol_f=1e-10)

    def loss(p, k):
        model, q0, v0, _ = build(p)
        sol = nsga_jax.integrate(model, dataclasses.replace(mj, krylov_min_dof=k), 0.0, 0.0006, 3e-5, q0, v0,
                                 n_steps=20)
        v = sol.v[-1].reshape(-1, 3)
        return jnp.mean(v[:, 2] ** 2) + jnp.mean(v[:, 0])

    grads = {k: jax.jit(jax.grad(lambda p: loss(p, k)))(params) for k in (0, None)}
    for name in params:
        assert abs(float(grads[None][name])) > 1e-5, name
        np.testing.assert_allclose(float(grads[0][name]), float(grads[None][name]), rtol=1e-8, err_msg=name)


@pytest.mark.slow
@pytest.mark.parametrize("mu", [0.0, 0.3], ids=["frictionless", "sliding"])
@pytest.mark.parametrize("scheme", [nsga_jax.DS(tol_r=1e-10, tol_f=1e-10), nsga_jax.DSn(tol_r=1e-10, tol_f=1e-10),
                                    nsga_jax.MJ(tol_r=1e-10, tol_f=1e-10)], ids=["ds", "dsn", "mj"])
def test_event_gradient_of_the_landing_matches_the_dense_path(scheme, mu):
    """ImpactTimeAdjoint on the matrix-free path: d/dE of the landing cube's
    final velocities equals the dense path's, frictionless and sliding (μ =
    0.3: the nine contacts stick at the landing, their slip after it exactly
    0, where the norm's derivative had made both paths' gradients NaN). With
    friction (DS, DSn) it is also the central difference of the discrete run to
    first order in h (the event gradient rebuilds the impact step in
    continuous time; measured: 2.9 % apart at h = 3e-5 s, 1.5 % at 1.5e-5,
    0.74 % at 7.5e-6)."""
    from nsga_jax.scenes import parametrize

    base = {"h": 3e-5, "t_end": 0.0006, "height": 0.0505, "velocity": -2.43, "divisions": 2, "vx": 0.5, "mu": mu}
    params, build = parametrize("flexible_cube", base, ["E"])

    def loss(p, k, adjoint=nsga_jax.ImpactTimeAdjoint()):
        model, q0, v0, _ = build(p)
        sol = nsga_jax.integrate(model, dataclasses.replace(scheme, krylov_min_dof=k), 0.0, 0.0006, 3e-5, q0, v0,
                                 n_steps=20, adjoint=adjoint)
        v = sol.v[-1].reshape(-1, 3)
        return jnp.mean(v[:, 2] ** 2) + jnp.mean(v[:, 0])

    grads = {k: float(jax.jit(jax.grad(lambda p: loss(p, k)))(params)["E"]) for k in (0, None)}
    assert np.isfinite(grads[None]) and abs(grads[None]) > 1e-5
    np.testing.assert_allclose(grads[0], grads[None], rtol=1e-8)
    if mu and isinstance(scheme, nsga_jax.DS):  # DSn is a DS
        forward = jax.jit(lambda p: loss(p, None, nsga_jax.DiscreteAdjoint()))
        step = 1e-4 * float(params["E"])
        fd = (float(forward({"E": params["E"] + step})) - float(forward({"E": params["E"] - step}))) / (2 * step)
        assert abs(grads[None] - fd) < 0.05 * abs(fd)
