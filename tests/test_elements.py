"""Element patch and consistency tests: rigid motions, analytic stretch and
cantilever, and jacfwd tangents against finite differences."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from reference_models import PlanarBeam

from nsga_jax._elements.beam2d import beam_internal_force
from nsga_jax._elements.hex8 import hex8_geometry, hex8_internal_force, lame, structured_hex_mesh
from nsga_jax._elements.rigid_body import (
    angular_velocity,
    box_inertia,
    box_vertices,
    natural_mass_matrix,
    natural_velocities,
    point_position,
    rigidity_constraints,
)


def fd_jacobian(f, x, eps=1e-6):
    """Central differences, all columns at once."""
    d = eps * jnp.eye(x.shape[0])
    return np.asarray(jax.jit(jax.vmap(lambda di: (f(x + di) - f(x - di)) / (2 * eps)))(d)).T


# ---------------------------------------------------------------- beam


def beam(n_elements=8, **kw):
    E, nu, A, I = 2.1e11, 0.3, 1e-4, 8.33e-10
    args = dict(EA=E * A, GAs=E / (2 * (1 + nu)) * 5 / 6 * A, EI=E * I, length=1.0, rhoA=7800 * A,
                rhoI=7800 * I, gravity=0.0, root=np.zeros(2), angle=0.0, wall_x=2.0, side=-1.0, e=0.0,
                tip_load=np.zeros(3), n_elements=n_elements, pinned=False, wall=False)
    args.update(kw)
    return PlanarBeam(**args)


def test_beam_rigid_motions_give_zero_force():
    model = beam(angle=0.3)
    q_ref = model.reference().reshape(-1, 3)
    zero = jnp.zeros(model.n_dof)
    scale = float(model.EA)  # force scale of a unit strain
    forces = jax.jit(lambda q: model.elements.forces(beam_internal_force, q, zero, model.n_dof))
    # translation
    q = (q_ref + jnp.array([0.7, -0.2, 0.0])).reshape(-1)
    assert np.abs(forces(q)).max() < 1e-12 * scale
    # rotation of the whole beam by 1 rad about an arbitrary point
    a = 1.0
    R = jnp.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    xy = (q_ref[:, :2] - jnp.array([0.2, 0.1])) @ R.T + jnp.array([0.2, 0.1])
    q = jnp.concatenate([xy, q_ref[:, 2:] + a], axis=1).reshape(-1)
    assert np.abs(forces(q)).max() < 1e-12 * scale


def test_beam_tangent_matches_finite_differences():
    model = beam(n_elements=1)
    p = jax.tree_util.tree_map(lambda x: x[0], model.elements.params)
    x = jnp.array([0.01, -0.02, 0.1, 0.98, 0.05, 0.3])
    v = jnp.zeros(6)
    K_ad = -jax.jit(jax.jacfwd(beam_internal_force))(x, v, p)
    K_fd = -fd_jacobian(lambda y: beam_internal_force(y, v, p), x, eps=1e-7)
    np.testing.assert_allclose(K_ad, K_fd, rtol=1e-5, atol=1e-6 * np.abs(K_ad).max())
    np.testing.assert_allclose(K_ad, K_ad.T, rtol=1e-12, atol=1e-9)  # Hessian of an energy


def test_timoshenko_cantilever_tip_deflection():
    P = 1e-3  # N, small: linear regime
    model = beam(n_elements=32, clamped=True, tip_load=np.array([0.0, -P, 0.0]))
    q = model.reference()
    free = np.arange(3, model.n_dof)
    zero = jnp.zeros_like(q)
    linearise = jax.jit(lambda q: (model.force(q, zero, 0.0), model.tangents(q, zero, 0.0)[0]))
    for _ in range(5):  # Newton on the static equilibrium f(q) = 0
        f, K = linearise(q)
        dq = np.linalg.solve(np.asarray(K)[np.ix_(free, free)], np.asarray(f)[free])
        q = q.at[free].add(dq)
    deflection = -float(q[-2])
    L, EI, GAs = 1.0, float(model.EI), float(model.GAs)
    exact = P * L**3 / (3 * EI) + P * L / GAs
    assert deflection == pytest.approx(exact, rel=1e-2)


# ---------------------------------------------------------------- hex8


def hex_params(E=90.0, nu=0.3):
    nodes, conn = structured_hex_mesh((0.02, 0.03, 0.04), (1, 1, 1), (0.1, -0.2, 0.3))
    X = jnp.asarray(nodes[conn[0]])
    dNdX, dV = hex8_geometry(X)
    lam, mu = lame(E, nu)
    return X, (dNdX, dV, lam, mu, 1.0)


def test_hex8_rigid_rotation_gives_zero_force():
    X, p = hex_params()
    R = jnp.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90° about z
    x = (X @ R.T + jnp.array([1.0, 2.0, 3.0])).reshape(-1)
    f = hex8_internal_force(x, jnp.zeros(24), p)
    assert np.abs(f).max() < 1e-14 * 90.0


def test_hex8_uniaxial_stretch_gives_E_eps_A():
    E, nu, eps = 90.0, 0.3, 1e-7
    X, p = hex_params(E, nu)
    x = (X * jnp.array([1 + eps, 1 - nu * eps, 1 - nu * eps])).reshape(-1)  # uniaxial stress state
    f = hex8_internal_force(x, jnp.zeros(24), p).reshape(8, 3)
    face = np.isclose(X[:, 0], X[:, 0].max())
    area = 0.03 * 0.04
    assert -float(f[face, 0].sum()) == pytest.approx(E * eps * area, rel=1e-5)


def test_hex8_tangent_matches_finite_differences():
    X, p = hex_params()
    rng = np.random.default_rng(0)
    x = (X + 0.003 * rng.normal(size=X.shape)).reshape(-1)  # a large, distorted state
    v = jnp.zeros(24)
    K_ad = -jax.jit(jax.jacfwd(hex8_internal_force))(x, v, p)
    K_fd = -fd_jacobian(lambda y: hex8_internal_force(y, v, p), x, eps=1e-7)
    np.testing.assert_allclose(K_ad, K_fd, rtol=1e-5, atol=1e-6 * np.abs(K_ad).max())


# ---------------------------------------------------------------- rigid body


def test_natural_coordinates_kinetic_energy_and_constraints():
    m, sides = 46.8, jnp.array([0.1, 0.2, 0.3])
    J = box_inertia(m, sides)
    M = natural_mass_matrix(m, J)
    a = 0.7
    R = jnp.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    q = jnp.concatenate([jnp.array([0.1, 0.2, 1.0]), R[:, 0], R[:, 1], R[:, 2]])
    assert np.abs(rigidity_constraints(q, 1.0)).max() < 1e-15
    omega, v = jnp.array([3.0, -2.0, 5.0]), jnp.array([1.0, 0.5, -0.3])
    qdot = natural_velocities(R, omega, v)
    body_omega = R.T @ omega
    expected = 0.5 * m * v @ v + 0.5 * body_omega @ J @ body_omega
    assert 0.5 * qdot @ M @ qdot == pytest.approx(float(expected), rel=1e-13)
    np.testing.assert_allclose(angular_velocity(q, qdot), omega, rtol=1e-13)
    # rigidity holds at velocity level for a rigid motion
    G = jax.jacfwd(rigidity_constraints)(q, 1.0)
    assert np.abs(G @ qdot).max() < 1e-13
    # vertex positions
    X = box_vertices(sides)
    assert np.allclose(point_position(q, X[7]), q[:3] + R @ jnp.array([0.05, 0.1, 0.15]))
