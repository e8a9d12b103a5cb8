"""Element functions, their jacfwd tangents, assembly, and the linear fast path."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import GenericBar
from reference_models import ElasticBar

import nsga_jax as nj
from nsga_jax._elements import bar_internal_force

BAR = dict(E=900.0, rho=1.0, area=1.0, length=10.0, gap0=5.005, e=0.0, n_elements=20)


def test_element_tangent_matches_finite_differences():
    p = (jnp.asarray(900.0), jnp.asarray(0.05), jnp.asarray(1.0))
    u = jnp.array([0.3, 0.31])
    v = jnp.zeros(2)
    K_ad = -jax.jacfwd(bar_internal_force)(u, v, p)
    eps = 1e-6
    K_fd = np.stack([-(bar_internal_force(u + eps * d, v, p) - bar_internal_force(u - eps * d, v, p)) / (2 * eps)
                     for d in jnp.eye(2)], axis=1)
    np.testing.assert_allclose(K_ad, K_fd, rtol=1e-7)


def test_assembled_bar_matrices():
    model = ElasticBar(**BAR)
    n = model.n_dof
    q = jnp.zeros(n)
    K, C = model.tangents(q, q, 0.0)
    k = 900.0 / 0.5
    expected = k * (np.diag(np.r_[1, 2 * np.ones(n - 2), 1]) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1))
    np.testing.assert_allclose(K, expected, rtol=1e-14)
    assert np.all(np.asarray(C) == 0.0)
    M = np.asarray(model.mass(q))
    assert np.ones(n) @ M @ np.ones(n) == pytest.approx(10.0)  # total mass
    # rigid translation: no internal force
    assert np.abs(model.force(jnp.full(n, 3.7), q, 0.0)).max() < 1e-11
    # f = -K q for the linear element
    u = jnp.asarray(np.random.default_rng(0).normal(size=n))
    np.testing.assert_allclose(model.force(u, q, 0.0), -K @ u, atol=1e-10)


def test_fast_path_equals_generic_path():
    fast_model = ElasticBar(**BAR)
    generic_model = GenericBar(**BAR)
    q0, v0 = np.zeros(fast_model.n_dof), np.full(fast_model.n_dof, 10.0)
    fast = nj.simulate(fast_model, nj.DS(), 0.0, 1.3, 2e-3, q0, v0)
    generic = nj.simulate(generic_model, nj.DS(), 0.0, 1.3, 2e-3, q0, v0)
    assert fast.impulse[:, 0].sum() > 150.0  # the contact is in the window
    np.testing.assert_allclose(fast.q, generic.q, atol=1e-9)
    np.testing.assert_allclose(fast.v, generic.v, atol=1e-7)
    np.testing.assert_allclose(fast.impulse, generic.impulse, atol=1e-7)


def _scene_groups():
    from nsga_jax.scenes import load_scene

    return {name: load_scene(name).model.bodies[0].elements
            for name in ("impacting_bar", "flexible_pendulum", "flexible_cube")}


def test_chains_are_recognised_from_their_dof_maps():
    from nsga_jax._assembly import StaticIndex, chain_layout

    groups = _scene_groups()
    assert chain_layout(groups["impacting_bar"].dofs) == (0, 1)
    assert chain_layout(groups["flexible_pendulum"].dofs) == (0, 3)
    assert chain_layout(groups["flexible_cube"].dofs) is None
    assert chain_layout(StaticIndex([[0, 1], [2, 3]])) is None  # disjoint elements
    assert chain_layout(StaticIndex([[4, 5, 6, 7], [6, 7, 8, 9]])) == (4, 2)


@pytest.mark.parametrize("offset, s, n_el, tail", [(0, 1, 7, 0), (0, 3, 4, 0), (2, 2, 3, 3), (0, 2, 1, 0)])
def test_chain_matrix_assembly_equals_the_scatter_add(offset, s, n_el, tail):
    """A chain's block-tridiagonal layout gives exactly the scatter-add's matrix."""
    from nsga_jax._assembly import StaticIndex, chain_layout, scatter_matrix

    dofs = offset + s * np.arange(n_el)[:, None] + np.arange(2 * s)[None, :]
    n = int(dofs.max()) + 1 + tail
    index = StaticIndex(dofs)
    assert chain_layout(index) == (offset, s)
    me = np.random.default_rng(s).normal(size=(n_el, 2 * s, 2 * s))
    expected = np.zeros((n, n))
    np.add.at(expected, (dofs[:, :, None], dofs[:, None, :]), me)
    np.testing.assert_array_equal(jax.jit(scatter_matrix, static_argnums=(0, 2))(index, jnp.asarray(me), n), expected)


@pytest.mark.parametrize("offset, s, n_el, tail",
                         [(0, 1, 7, 0), (0, 3, 4, 0), (2, 2, 3, 3), (0, 2, 1, 0), (None, 2, 3, 0)])
def test_quadratic_form_equals_that_of_the_assembled_matrix(offset, s, n_el, tail):
    """Σ_e x_eᵀ A_e x_e, read by slices for a chain (``offset``) and by a
    gather otherwise (``None``: elements in a scattered order), is xᵀ A x of
    the assembled A, also under vmap."""
    from nsga_jax._assembly import ElementGroup, StaticIndex, chain_layout, scatter_matrix

    rng = np.random.default_rng(s + n_el)
    if offset is None:
        dofs = rng.permutation(2 * s * n_el).reshape(n_el, 2 * s)
    else:
        dofs = offset + s * np.arange(n_el)[:, None] + np.arange(2 * s)[None, :]
    n = int(dofs.max()) + 1 + tail
    group = ElementGroup(dofs=StaticIndex(dofs), params=jnp.asarray(rng.normal(size=(n_el, 2 * s, 2 * s))))
    assert (chain_layout(group.dofs) is None) == (offset is None)
    A = scatter_matrix(group.dofs, group.params, n)
    x = jnp.asarray(rng.normal(size=(3, n)))
    form = jax.jit(jax.vmap(lambda x: group.quadratic_form(lambda p: p, x)))(x)
    np.testing.assert_allclose(form, jnp.einsum("bi,ij,bj->b", x, A, x), rtol=1e-12)
