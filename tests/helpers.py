"""Small models used only by the tests."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from reference_models import ElasticBar

from nsga_jax._models import Model


class Oscillator(Model):
    """Undamped linear oscillator m q'' + k q = 0 (one coordinate)."""

    m: float = eqx.field(converter=jnp.asarray)
    k: float = eqx.field(converter=jnp.asarray)

    n_dof = 1
    constant_mass = True
    linear_force = True
    linear_constraints = True

    @property
    def mbar(self):
        return self.m

    def mass(self, q):
        return self.m * jnp.eye(1)

    def force(self, q, v, t):
        return -self.k * q


class GenericBar(ElasticBar):
    """The elastic bar with its structure flags off: takes the generic (refactorising) path."""

    @property
    def constant_mass(self):
        return False

    @property
    def linear_force(self):
        return False

    @property
    def linear_constraints(self):
        return False


def spd_system(n: int, seed: int):
    """A random symmetric positive definite matrix A = B Bᵀ + n I (n, n) and
    a right-hand side (n,), reproducible from ``seed``."""
    rng = np.random.default_rng(seed)
    b = rng.normal(size=(n, n))
    return jnp.asarray(b @ b.T + n * np.eye(n)), jnp.asarray(rng.normal(size=n))


def assert_blocks_equal_assembled(model, q) -> None:
    """A matrix-free model's element blocks of M and K(q), and their node
    blocks, equal the assembled matrices: entries, products and diagonal."""
    M = model.mass(q)
    K, _ = model.tangents(q, jnp.zeros_like(q), 0.0)
    x = jnp.asarray(np.random.default_rng(1).standard_normal(model.n_dof))
    for blocks, dense in ((model.element_mass(q), M), (model.element_stiffness(q), K)):
        scale = float(jnp.abs(dense).max())
        for form in (blocks, blocks.node_blocks()):
            np.testing.assert_allclose(form.dense(), dense, rtol=0, atol=1e-13 * scale)
            np.testing.assert_allclose(form.mv(x), dense @ x, rtol=0, atol=1e-12 * scale)
            np.testing.assert_allclose(form.diagonal(), jnp.diagonal(dense), rtol=0, atol=1e-13 * scale)
        np.testing.assert_allclose(blocks.node_blocks().frobenius_norm(), jnp.linalg.norm(dense), rtol=1e-13)
