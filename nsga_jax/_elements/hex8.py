"""Trilinear hexahedron, total Lagrangian, St Venant–Kirchhoff material.

Element coordinates ``x_e`` (24,): current positions of the 8 nodes, node-major
(``x_e[3 a + i]``); parameters ``p = (dNdX, dV, lam, mu, rho)``: the reference
shape-function gradients at the Gauss points (8, 8, 3) and the Gauss weights
times det(dX/dξ) (8,) [m³] -- both from :func:`hex8_geometry`, computed once
from the reference node positions -- the Lamé constants [Pa] and the density
[kg/m³]. Node order: (-,-,-), (+,-,-), (+,+,-), (-,+,-), then the same at
ζ = +1. Full 2×2×2 Gauss integration.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._blocks import ElementMatrix

_CORNERS = np.array(
    [[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1], [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]],
    dtype=float,
)
_G = 1.0 / np.sqrt(3.0)
GAUSS_POINTS = _CORNERS * _G  # (8, 3); all weights are 1


def shape_functions(xi: jax.Array) -> jax.Array:
    """N_a(ξ), shape (8,)."""
    return jnp.prod(1.0 + jnp.asarray(_CORNERS, xi.dtype) * xi, axis=1) / 8.0


def shape_gradients(xi: jax.Array) -> jax.Array:
    """dN_a/dξ_j, shape (8, 3)."""
    return jax.jacfwd(shape_functions)(xi)


def hex8_geometry(X_e: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Reference geometry of an element with nodes X_e (8, 3): dN/dX at each Gauss
    point (8, 8, 3) and the integration weights det(dX/dξ) (8,) [m³]."""
    dN = jax.vmap(shape_gradients)(jnp.asarray(GAUSS_POINTS, jnp.result_type(X_e, float)))  # (gp, a, j)
    J = jnp.einsum("ai,gaj->gij", X_e, dN)  # dX_i/dξ_j
    dNdX = jnp.einsum("gaj,gji->gai", dN, jnp.linalg.inv(J))
    return dNdX, jnp.linalg.det(J)


def element_volume(X_e: jax.Array) -> jax.Array:
    """Reference volume [m³] of the element with node positions X_e (8, 3)."""
    return jnp.sum(hex8_geometry(X_e)[1])


def _deformation(x_e: jax.Array, p) -> tuple[jax.Array, jax.Array, jax.Array]:
    """F, the Green–Lagrange strain E = (FᵀF - I)/2 and the second
    Piola–Kirchhoff stress S = λ tr(E) I + 2μ E [Pa] at the Gauss points,
    each shape (8, 3, 3)."""
    dNdX, _, lam, mu, _ = p
    F = jnp.einsum("ai,gaj->gij", x_e.reshape(8, 3), dNdX)
    eye = jnp.eye(3, dtype=F.dtype)
    E = 0.5 * (jnp.einsum("gki,gkj->gij", F, F) - eye)
    S = lam * jnp.trace(E, axis1=1, axis2=2)[:, None, None] * eye + 2.0 * mu * E
    return F, E, S


def svk_energy(x_e: jax.Array, p) -> jax.Array:
    """Strain energy [J]: Σ_gp (λ/2 (tr E)² + μ E:E) dV, E = (FᵀF - I)/2."""
    _, dV, lam, mu, _ = p
    _, E, _ = _deformation(x_e, p)
    trE = jnp.trace(E, axis1=1, axis2=2)
    W = 0.5 * lam * trE**2 + mu * jnp.sum(E * E, axis=(1, 2))
    return jnp.sum(W * dV)


def hex8_internal_force(x_e: jax.Array, v_e: jax.Array, p) -> jax.Array:
    """Internal force (24,) = -dU/dx_e [N] of :func:`svk_energy`, in closed
    form: f_a = -Σ_gp dV F S ∇N_a (the first Piola–Kirchhoff stress F S on
    the shape-function gradients), faster than ``jax.grad`` of the energy
    (measured in docs/performance.md, *Cost and memory against size*)."""
    dNdX, dV = p[0], p[1]
    F, _, S = _deformation(x_e, p)
    P = jnp.einsum("gij,gjk->gik", F, S) * dV[:, None, None]
    return -jnp.einsum("gik,gak->ai", P, dNdX).reshape(24)


def hex8_stiffness(x_e: jax.Array, p) -> jax.Array:
    """Tangent stiffness K_e = -d(internal force)/dx_e = d²U/dx_e², shape (24, 24) [N/m],
    in closed form: with F and S = λ tr(E) I + 2μ E at each Gauss point and
    g_a = F ∇N_a,

        K[a i, b k] = Σ_gp dV (δ_ik ∇N_a·S ∇N_b + λ g_ai g_bk + μ (F Fᵀ)_ik ∇N_a·∇N_b + μ g_bi g_ak),

    the geometric and the material parts. The same matrix as ``jax.jacfwd``
    of :func:`hex8_internal_force`, in a fraction of its time
    (``experiments/benchmarks/bench_large_kernels.py``, its table in
    docs/results/bench/large_kernels.md)."""
    dNdX, dV, lam, mu, _ = p
    F, _, S = _deformation(x_e, p)
    g = jnp.einsum("gij,gaj->gai", F, dNdX)  # F ∇N_a
    geometric = jnp.einsum("g,gaj,gjl,gbl->ab", dV, dNdX, S, dNdX)
    grad_dot = jnp.einsum("gaj,gbj->gab", dNdX, dNdX)
    FFt = jnp.einsum("gij,gkj->gik", F, F)
    K = (jnp.einsum("ab,ik->aibk", geometric, jnp.eye(3, dtype=F.dtype))
         + lam * jnp.einsum("g,gai,gbk->aibk", dV, g, g)
         + mu * jnp.einsum("g,gik,gab->aibk", dV, FFt, grad_dot)
         + mu * jnp.einsum("g,gbi,gak->aibk", dV, g, g))
    return K.reshape(24, 24)


def hex8_mass_blocks(group, n: int) -> ElementMatrix:
    """The consistent mass of a group of hex8 elements (an
    :class:`~nsga_jax._assembly.ElementGroup`), element by element, never
    assembled; n coordinates, 3 a node."""
    return ElementMatrix(group.matrix_blocks(hex8_mass), group.dofs, n, 3)


def hex8_stiffness_blocks(group, q: jax.Array, n: int) -> ElementMatrix:
    """The tangent stiffness :func:`hex8_stiffness` of a group at the
    coordinates q (n,), element by element, never assembled."""
    return ElementMatrix(jax.vmap(hex8_stiffness)(group.gather(q), group.params), group.dofs, n, 3)


def _gauss_shape_functions(dtype) -> jax.Array:
    return jax.vmap(shape_functions)(jnp.asarray(GAUSS_POINTS, dtype))  # (gp, a)


def hex8_mass(p) -> jax.Array:
    """Consistent mass matrix (24, 24) [kg]."""
    _, dV, _, _, rho = p
    real = jnp.result_type(dV, rho)  # the element's precision
    N = _gauss_shape_functions(real)
    return jnp.kron(rho * jnp.einsum("g,ga,gb->ab", dV, N, N), jnp.eye(3, dtype=real))


def hex8_body_force(p, acceleration: jax.Array) -> jax.Array:
    """Consistent nodal load (24,) of a uniform body acceleration (3,) [m/s²] (gravity)."""
    _, dV, _, _, rho = p
    N = _gauss_shape_functions(jnp.result_type(dV, rho))
    return jnp.kron(rho * jnp.einsum("g,ga->a", dV, N), acceleration)


def lame(E: jax.Array, nu: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Lamé constants (λ, μ) from Young's modulus and Poisson's ratio."""
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))


def structured_hex_mesh(sides, divisions, origin=(0.0, 0.0, 0.0)):
    """Nodes (N, 3) and connectivity (E, 8) of a box meshed with nx × ny × nz hexahedra.

    Node index ``i + (nx+1) (j + (ny+1) k)`` for grid indices (i, j, k).
    """
    nx, ny, nz = divisions
    axes = [np.linspace(o, o + s, n + 1) for o, s, n in zip(origin, sides, divisions)]
    k, j, i = np.meshgrid(np.arange(nz + 1), np.arange(ny + 1), np.arange(nx + 1), indexing="ij")
    nodes = np.stack([axes[0][i.ravel()], axes[1][j.ravel()], axes[2][k.ravel()]], axis=1)

    def index(i, j, k):
        return i + (nx + 1) * (j + (ny + 1) * k)

    elements = []
    for kk in range(nz):
        for jj in range(ny):
            for ii in range(nx):
                elements.append([
                    index(ii, jj, kk), index(ii + 1, jj, kk), index(ii + 1, jj + 1, kk), index(ii, jj + 1, kk),
                    index(ii, jj, kk + 1), index(ii + 1, jj, kk + 1), index(ii + 1, jj + 1, kk + 1),
                    index(ii, jj + 1, kk + 1),
                ])
    return nodes, np.asarray(elements, dtype=np.int64)
