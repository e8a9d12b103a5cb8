"""The matrix-free path (nsga_jax/_system/matrix_free.py,
nsga_jax/_integrators/krylov.py) on systems of several flexible bodies:
the stacked element blocks and the contact rows equal the assembled
matrices and the constraint Jacobian, the switch follows the parts (one kind
of body), and two cubes landing on a floor run as on the dense path, to
the Newton tolerance, with the same contacts closing."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

import nsga_jax
from nsga_jax._integrators.krylov import KRYLOV_KINDS
from nsga_jax.system import Gravity, HexSolid, PlaneContact, RigidBody3D, System

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
    M = model.mass(q)
    K, _ = model.tangents(q, jnp.zeros_like(q), 0.0)
    x = jnp.asarray(np.random.default_rng(1).standard_normal(model.n_dof))
    for blocks, dense in ((model.element_mass(q), M), (model.element_stiffness(q), K)):
        scale = float(jnp.abs(dense).max())
        for form in (blocks, blocks.node_blocks()):
            np.testing.assert_allclose(form.dense(), dense, rtol=0, atol=1e-13 * scale)
            np.testing.assert_allclose(form.mv(x), dense @ x, rtol=0, atol=1e-12 * scale)
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
