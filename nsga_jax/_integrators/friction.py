"""Coulomb friction in the velocity-level sub-problems: the Alart–Curnier
augmented Lagrangian and its semi-smooth Newton correction.

A frictional contact j has a normal impulse P_N,j (its row of the velocity
jump's multipliers, eq. 42) and a tangential impulse P_T,j in the contact's
tangent space (1 direction in a planar system, 2 in space), with the slip
velocity γ_T,j = g_T,j(q) v. Coulomb's law at impulse level,

    |P_T,j| <= μ_j P_N,j,   P_T,j = -μ_j P_N,j γ_T,j / |γ_T,j| where γ_T,j ≠ 0,

is written, as Alart and Curnier do, as a projection of the augmented
tangential multiplier on the disk of radius μ_j P_N,j:

    σ_T = kv Λ_T - p_T γ_T,    P_T = proj_{D(μ P_N)}(σ_T),
    residual row  -(kv/p_T) (kv Λ_T - P_T)  = 0,

with the penalty p_T,j the contact's own effective mass (:func:`contact_masses`),

which is -kv γ_T (stick: the slip velocity vanishes) inside the disk,
the slip law on its edge, and -(kv²/p_T) Λ_T (no impulse) on an open contact
(P_N = 0). The normal part is the frictionless law of eq. 42 unchanged:
σ_N = kv Λ_N - pv ġ_N, P_N = σ_N on the active set. The multipliers of a
velocity sub-problem are then ``[Λ_N (nc); Λ_T (nf · d)]`` and its reaction
``g_q^T P_N + g_T^T P_T``.

Newton's correction eliminates the coordinates by a Schur complement, as for
the frictionless bordered systems (:func:`~nsga_jax._integrators.linalg.solve_bordered`),
but with the law's generalised Jacobian: with y = A^{-1} r₁, B = A^{-1} G^T and
the Delassus matrix D = G B on all contact rows (normal and tangential),

    [ I - P_γ D    -P_Λ ] [dP]   [ -P_γ G y        ]
    [ R_γ D         R_Λ ] [dΛ] = [ -r_c + R_γ G y  ],    dW = -y + B dP,

where P_Λ, P_γ (R_Λ, R_γ) are the derivatives of the impulses P (of the
contact residual rows r_c) in the multipliers and the rates, taken by
``jax.jacfwd`` of the local law with its normal rows closed on
:func:`~nsga_jax._integrators.contact_law.linearised_active` (a contact at
σ_N = ±round-off is linearised as closed whatever the sign). The system has 2 (nc + nf · d) unknowns;
what the model has no friction for never reaches this module.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax

from .._custom_types import Scalar, Vector
from .._models.base import Model
from .contact_law import NormalLaw, linearised_active
from .linalg import AbstractFactorisation, linear_solve, minimum_norm_split, redundancy_shift
from .newton import Problem, Residual, convergence_bound, where_needed

PIVOT_FRACTION = 0.1
"""A Newton system of the contact law whose inconsistent part exceeds this
fraction of the sub-problem's tolerance gets the pivot of
:meth:`FrictionLaw.first_slip` (the part is measured on the law's rows, not
on the residual's, hence the margin)."""

RESTART_PENALTIES = (0.3, 3.0)
"""The factors on the tangential penalties p_T of a sub-problem's further
Newton runs, each from its start, when the one before stalls
(:attr:`~nsga_jax._integrators.newton.Problem.restart`). The penalty leaves
the solution unchanged (Λ_T = P_T / k there) and changes Newton's path: ten
planar boxes with the top one pushed (``box_stack``, h = 1e-3 s, 3 s) failed
45 of 3,000 steps in 2-cycles between a contact's stick and slip branches;
with the restarts none fails (docs/friction.md)."""

SLIP_MARGIN = 1e-3
"""How far past the edge of its disk :meth:`FrictionLaw.first_slip` moves the
first contact to slide, relative to the step that reaches the edge."""


def disk_projection(sigma: jax.Array, radius: jax.Array) -> jax.Array:
    """Projection of each row of ``sigma`` (nf, d) on the disk (segment for
    d = 1) of radius ``radius`` (nf,) >= 0 about the origin. A zero radius
    projects on the origin with a zero derivative (a frictionless contact's
    law); the norm is taken safely at σ = 0."""
    s2 = jnp.sum(sigma**2, axis=-1)
    inside = (s2 <= radius**2) & (radius > 0)
    norm = jnp.sqrt(jnp.where(s2 > 0, s2, 1.0))
    return jnp.where(inside[:, None], sigma, (radius / norm)[:, None] * sigma)


class LawParts(NamedTuple):
    """The local contact law's output: the impulses P (nc + nf·d) [N s] that
    act on the coordinates, the contact residual rows r_c, the normal active
    set (nc,) and the normal augmented multiplier σ_N (nc,)."""

    impulse: jax.Array
    rows: jax.Array
    active: jax.Array
    aug: jax.Array


def contact_law(lam: jax.Array, rate: jax.Array, candidates, unilateral, mu: jax.Array,
                normals: tuple[int, ...], d: int, k: Scalar, p: Scalar, p_t: jax.Array,
                linearised: bool = False, stuck: jax.Array | None = None) -> LawParts:
    """The velocity-level law of every contact row at the multipliers ``lam``
    and rates ``rate`` (both nc + nf·d): eq. 42's normal law (scaling k,
    penalty p) and Alart–Curnier's tangential one (penalty p_t (nf,) per
    contact, :func:`contact_masses`; module docstring). ``linearised``
    (static): the same values, with the normal rows' derivatives taken on
    :func:`~nsga_jax._integrators.contact_law.linearised_active` (Newton's
    matrix) instead of the active set. ``stuck`` (nf,) bool, or ``None``:
    contacts held sticking whatever their normal multiplier (P_T = σ_T: no
    slip), the position correction's contacts that the smooth motion held
    sticking (:mod:`~nsga_jax._integrators.persistent_contacts`). A contact
    whose normal row is marked bilateral there (pinned) may pull: its disk's
    radius is μ max(P_N, 0)."""
    nc = unilateral.shape[0]
    lam_n, rate_n = lam[:nc], rate[:nc]
    aug = k * lam_n - p * rate_n
    active = candidates & (~unilateral | (aug >= 0))

    def normal_law(closed):
        return jnp.where(closed, aug, 0.0), jnp.where(closed, -k * rate_n, -(k**2 / p) * lam_n)

    P_n, r_n = normal_law(active)
    if linearised:  # values of the active set, derivatives of the widened one
        P_lin, r_lin = normal_law(linearised_active(aug, candidates, unilateral))
        P_n = P_lin + lax.stop_gradient(P_n - P_lin)
        r_n = r_lin + lax.stop_gradient(r_n - r_lin)
    if rate.shape[0] == nc:
        return LawParts(P_n, r_n, active, aug)
    lam_t, rate_t = lam[nc:].reshape(-1, d), rate[nc:].reshape(-1, d)
    sigma_t = k * lam_t - p_t[:, None] * rate_t
    P_normal, open_ = P_n[jnp.asarray(normals)], unilateral[jnp.asarray(normals)]
    P_t = disk_projection(sigma_t, mu * jnp.where(open_, P_normal, jnp.maximum(P_normal, 0.0)))
    if stuck is not None:
        P_t = jnp.where(stuck[:, None], sigma_t, P_t)
    r_t = -(k / p_t[:, None]) * (k * lam_t - P_t)
    return LawParts(jnp.concatenate([P_n, P_t.ravel()]), jnp.concatenate([r_n, r_t.ravel()]), active, aug)


def contact_masses(mass_diagonal: jax.Array, GT: jax.Array, d: int) -> jax.Array:
    """The effective mass [kg] of each frictional contact's tangential
    motion, 1 / w_j with w_j ≈ g_T,j M^{-1} g_T,jᵀ from the diagonal of M
    (the mean over the contact's d tangents), shape (nf,): the tangential
    penalty of Alart and Curnier's law. Its value never changes the
    solution, only Newton's path, which a penalty far from the contact's own
    mass makes long or cyclic: a node of the 125-element cube weighs 1/200
    of the system's mass m̄, and with m̄ as penalty its velocity jumps
    stalled at the iteration cap."""
    w = jnp.sum(GT**2 / mass_diagonal, axis=1).reshape(-1, d).mean(axis=1)
    return 1.0 / jnp.maximum(w, jnp.finfo(w.dtype).tiny)


class FrictionLaw(NamedTuple):
    """A velocity-level sub-problem's contact law, bound to the model's
    friction structure: ``law(lam, rate)`` -> :class:`LawParts`."""

    candidates: jax.Array
    unilateral: jax.Array
    mu: jax.Array
    normals: tuple[int, ...]
    d: int
    k: Scalar
    p: Scalar
    p_t: jax.Array
    stuck: jax.Array | None = None

    @property
    def damped(self) -> bool:
        """Whether the Newton updates are damped (:attr:`~nsga_jax._integrators.newton.Problem.line_search`)."""
        return True

    @classmethod
    def of(cls, model: Model, candidates, unilateral, k: Scalar, p: Scalar, mass_diagonal: jax.Array | None,
           GT: jax.Array) -> "FrictionLaw":
        """The law with the normal scaling k and penalty p, and the tangential
        penalties from the mass diagonal (n,) and the tangent rows g_T (nf·d, n)
        (``mass_diagonal=None``: p for every contact)."""
        mu = jnp.asarray(model.friction_coefficients, GT.dtype)
        d = model.friction_dim
        nf = model.n_friction
        p_t = (jnp.full((nf,), p, GT.dtype) if mass_diagonal is None else contact_masses(mass_diagonal, GT, d))
        return cls(jnp.broadcast_to(candidates, unilateral.shape), unilateral, mu, model.friction_normals,
                   d, k, p, p_t)

    def rescaled(self, factor) -> "FrictionLaw":
        """The same law with its tangential penalties p_T times ``factor`` (a
        scalar, traced or not): the same solution, another Newton path
        (:data:`RESTART_PENALTIES`)."""
        return self._replace(p_t=jnp.asarray(factor, self.p_t.dtype) * self.p_t)

    def __call__(self, lam: jax.Array, rate: jax.Array, linearised: bool = False) -> LawParts:
        return contact_law(lam, rate, self.candidates, self.unilateral, self.mu, self.normals, self.d,
                           self.k, self.p, self.p_t, linearised, self.stuck)

    def residual(self, inertia: Vector, force: Vector, G: jax.Array, rate: jax.Array, lam: jax.Array,
                 tol_r, tol_f) -> Residual:
        """``[inertia - force - G^T P;  r_c]`` with ``aux = (active, σ_N, P_T)``."""
        parts = self(lam, rate)
        reaction = G.T @ parts.impulse
        r = jnp.concatenate([inertia - force - reaction, parts.rows])
        nc = self.unilateral.shape[0]
        return Residual(r, convergence_bound([inertia, force, reaction, parts.rows], tol_r, tol_f),
                        (parts.active, parts.aug, parts.impulse[nc:]))

    def correction(self, matrix: AbstractFactorisation, r1: Vector, r_c: jax.Array, G_up: jax.Array,
                   G_low: jax.Array, lam: jax.Array, rate: jax.Array, bound: Scalar | None) -> tuple[Vector, jax.Array]:
        """The semi-smooth Newton correction (dW, dΛ) (module docstring), with
        the law's derivatives at (lam, rate) and the coordinates eliminated
        through ``matrix`` (the top-left block A).

        Redundant contacts (more contact rows than the coordinates they move:
        two corners of a block, four of a box) make D singular. The system is
        solved with D + εI and D + 2εI (ε the
        :func:`~nsga_jax._integrators.linalg.redundancy_shift`, a vanishing
        contact compliance), whose solutions differ in their null-space part
        n/ε, n/2ε only, and extrapolated to the solution with no null-space
        part. Where that solution misses the system by more than a tenth of
        ``bound`` (the sub-problem's tolerance of eq. 51: the active set cannot
        hold, e.g. both corners of a landing block sticking), the minimum-norm
        solution and the null direction n are taken by SVD instead: the
        minimum-norm solution is the step where it changes the active set,
        else the multipliers are moved along ±n to the first contact that
        reaches the edge of its disk or opens (:meth:`first_slip`). ``bound = None``: the
        compliant solve alone (Moreau–Jean's one-level problem, and the
        impact-time rebuild, whose correction must be linear in r₁, r_c).
        docs/friction.md gives the reasoning."""
        y, B = matrix.solve_with_constraints(r1, G_up)
        if B.shape[1] < G_up.shape[0]:  # a constant matrix holds A^{-1} g_q^T only: add A^{-1} g_T^T
            B = jnp.concatenate([B, matrix.solve(G_up[B.shape[1]:].T)], axis=1)
        D = G_low @ B
        m = D.shape[0]
        (P_lam, P_rate), (R_lam, R_rate) = jax.jacfwd(lambda a, b: self(a, b, linearised=True)[:2],
                                                      argnums=(0, 1))(lam, rate)
        eye = jnp.eye(m, dtype=D.dtype)
        Gy = G_low @ y
        system = jnp.block([[eye - P_rate @ D, -P_lam], [R_rate @ D, R_lam]])
        rhs = jnp.concatenate([-P_rate @ Gy, -r_c + R_rate @ Gy])
        # redundant contacts make D singular: solved with D + εI and D + 2εI, whose solutions differ
        # in their null-space part n/ε, n/2ε, extrapolated away (module docstring)
        shift = redundancy_shift(D.dtype) * jnp.max(jnp.abs(jnp.diagonal(D)))

        def compliant_matrix(eps):
            Dc = D + eps * eye
            return jnp.block([[eye - P_rate @ Dc, -P_lam], [R_rate @ Dc, R_lam]])

        def compliant(eps):
            return linear_solve(compliant_matrix(eps), rhs)

        regular = compliant(shift)
        if bound is None:  # the compliant solve alone: Moreau-Jean, the impact-time rebuild (linear in r)
            return -y + B @ regular[:m], regular[m:]
        half = compliant(2.0 * shift)
        sol = 2.0 * half - regular  # the solution with no null-space part
        # ... to round-off relative to n/2ε: where that part exceeds the solution, the cancellation
        # leaves noise along n that the misfit below cannot see (it lies in the system's null space)
        # and that can exceed the friction disks' radii (rocking_block at h = 1e-3, step 2174: a
        # stick-slip cycle); it is projected out along n/2ε = x(ε) - x(2ε)
        null = regular - half
        nn = jnp.dot(null, null)
        noisy = (nn > 0) & (jnp.sqrt(nn) > jnp.linalg.norm(sol))
        sol = jnp.where(noisy, sol - null * jnp.dot(null, sol) / jnp.where(nn > 0, nn, 1.0), sol)
        # inconsistent beyond the tolerance: the active set cannot hold, pivot (module docstring);
        # then by SVD, as the extrapolation loses the solution's digits to the null part's size
        pivot = jnp.linalg.norm(system @ sol - rhs) > PIVOT_FRACTION * bound

        def pivoted():
            x0, null, _ = minimum_norm_split(system, rhs, compliant_matrix(shift))
            dW = -y + B @ x0[:m]
            # the minimum-norm point changes the active set already (a landing: the corner that must lift
            # is open there): it is the step; else the event along ±n with the smaller law rows
            changed = jnp.any(self(lam, rate).active != self(lam + x0[m:], rate + G_low @ dW).active)
            tau = jnp.where(changed, 0.0,
                            self.first_slip(lam + x0[m:], rate + G_low @ dW, null[m:], G_low @ (B @ null[:m]), bound))
            return x0 + lax.stop_gradient(tau) * null

        sol = where_needed(pivot, pivoted, sol)
        return -y + B @ sol[:m], sol[m:]

    def first_slip(self, lam: jax.Array, rate: jax.Array, d_lam: jax.Array, d_rate: jax.Array,
                   bound: Scalar) -> jax.Array:
        """The step τ (signed) along the null direction ±(d_lam, d_rate) from the
        law at (lam, rate) to the event where the law's rows are the smallest
        (:meth:`events`; 0 where there is none). A null direction's sign is
        arbitrary (an SVD's), so both ways count: with the events ahead only,
        a block landing flat with a high μ had its corners pushed apart until
        one slid, and Newton cycled between the branches of that corner's
        disk; with only the nearest event each way (a sticking contact
        reaching its edge), a block landing flat on a corner that carries
        almost nothing (its disk 20 times smaller than the other's) had its
        other corner pushed to the edge of its disk, where the light corner's
        multiplier, outside its own disk, was left outside: the position
        correction cycled at its cap (rocking block, h = 4e-3 s, tilt 0.05);
        the event where the light corner's multiplier reaches its edge is the
        solution's active set."""
        taus = self.events(lam, rate, d_lam, d_rate, bound)
        rows = jax.vmap(lambda tau: self.rows_along(lam, rate, d_lam, d_rate, tau))(jnp.where(jnp.isfinite(taus),
                                                                                             taus, 0.0))
        rows = jnp.where(jnp.isfinite(taus), rows, jnp.inf)
        best = jnp.argmin(rows)
        return jnp.where(jnp.isfinite(rows[best]), taus[best], 0.0)

    def rows_along(self, lam: jax.Array, rate: jax.Array, d_lam: jax.Array, d_rate: jax.Array,
                   tau: Scalar) -> jax.Array:
        """The norm of the law's residual rows at (lam + τ d_lam, rate + τ d_rate)."""
        return jnp.linalg.norm(self(lam + tau * d_lam, rate + tau * d_rate).rows)

    def events(self, lam: jax.Array, rate: jax.Array, d_lam: jax.Array, d_rate: jax.Array,
               bound: Scalar) -> jax.Array:
        """The steps τ (2 nf + nc,), signed, ∞ where there is none, at which
        the law at (lam + τ d_lam, rate + τ d_rate) changes its active set: an
        active frictional contact's augmented multiplier reaches the edge of
        its disk, |σ_T,j(τ)| = μ_j P_N,j(τ) (from inside: it starts to slide;
        from outside: it may stick), or an active contact's normal impulse
        reaches zero; each moved past its event by :data:`SLIP_MARGIN` of τ,
        or less where the law's rows would grow there by more than
        :data:`PIVOT_FRACTION` of ``bound`` (a high μ_j, whose disk shrinks
        fast along the direction: the overshoot alone would then be a residual
        far above the one the step leaves). Along a null direction of the
        Newton system of redundant contacts (module docstring) the coordinates
        do not move and the law is affine in τ, so each contact's condition is
        a quadratic in τ, with two roots. Contacts held sticking (``stuck``)
        have no edge to reach."""
        nc, d = self.unilateral.shape[0], self.d
        normals = jnp.asarray(self.normals)

        def sigma_and_radius(lam_, rate_):
            aug = self.k * lam_[:nc] - self.p * rate_[:nc]
            sigma = self.k * lam_[nc:].reshape(-1, d) - self.p_t[:, None] * rate_[nc:].reshape(-1, d)
            return sigma, self.mu * aug[normals]

        a, c = sigma_and_radius(lam, rate)
        b, e = sigma_and_radius(d_lam, d_rate)
        active = self(lam, rate).active
        frictional = active[normals] & (self.mu > 0)
        if self.stuck is not None:
            frictional = frictional & ~self.stuck
        qa = jnp.sum(b**2, axis=1) - e**2
        qb = 2.0 * (jnp.sum(a * b, axis=1) - c * e)
        qc = jnp.sum(a**2, axis=1) - c**2
        disc = qb**2 - 4.0 * qa * qc
        big = -0.5 * (qb + jnp.where(qb >= 0, 1.0, -1.0) * jnp.sqrt(jnp.maximum(disc, 0.0)))  # roots big/qa, qc/big
        inf = jnp.asarray(jnp.inf, a.dtype)

        def root(num, den):  # a root where the disk's radius is positive (not the mirrored cone's)
            tau = num / jnp.where(den != 0, den, 1.0)
            valid = frictional & (disc >= 0) & (den != 0) & jnp.isfinite(tau) & (tau != 0) & (c + tau * e > 0)
            return jnp.where(valid, tau, inf)

        # an active unilateral contact whose normal impulse falls to zero opens
        aug0 = self.k * lam[:nc] - self.p * rate[:nc]
        daug = self.k * d_lam[:nc] - self.p * d_rate[:nc]
        opens = active & self.unilateral & (aug0 > 0) & (daug != 0)
        opening = jnp.where(opens, -aug0 / jnp.where(opens, daug, 1.0), inf)
        taus = jnp.concatenate([root(big, qa), root(qc, big), opening])

        def past(tau):
            growth = (self.rows_along(lam, rate, d_lam, d_rate, (1.0 + SLIP_MARGIN) * tau)
                      - self.rows_along(lam, rate, d_lam, d_rate, tau))  # linear in the margin past the edge
            scale = jnp.where(growth > PIVOT_FRACTION * bound,
                              PIVOT_FRACTION * bound / jnp.where(growth > 0, growth, 1.0), 1.0)
            return (1.0 + SLIP_MARGIN * scale) * tau

        finite = jnp.isfinite(taus)
        return jnp.where(finite, jax.vmap(past)(jnp.where(finite, taus, 0.0)), inf)


def restarted(law: NormalLaw | FrictionLaw, build: Callable[[FrictionLaw], Problem]) -> dict:
    """The ``restart`` and ``restart_factors`` of a sub-problem built by
    ``build(law)``: the law with its tangential penalties times a factor,
    for each of :data:`RESTART_PENALTIES` (read when traced); none for the
    frictionless law."""
    if not isinstance(law, FrictionLaw) or not RESTART_PENALTIES:
        return {}
    return {"restart": lambda factor: build(law.rescaled(factor)), "restart_factors": tuple(RESTART_PENALTIES)}
