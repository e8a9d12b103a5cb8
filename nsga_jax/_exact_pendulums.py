"""Event-driven reference of the double pendulum of two uniform rods whose
lower tip strikes a vertical wall (scene ``double_pendulum``).

Minimal coordinates: the absolute angles θ1, θ2 [rad] of the two rods from
the downward vertical, positive counter-clockwise (toward +x at the bottom).
Rod 1 (mass m1, length l1) turns about a fixed pivot at the origin; rod 2
(m2, l2) is pinned to rod 1's lower end. Each rod is uniform (inertia
m l²/12 about its centre). Kinetic and potential energy:

    T = ½ θ̇ᵀ M(θ) θ̇,   M = [[(m1/3 + m2) l1²,  c cos(θ1 - θ2)],
                             [c cos(θ1 - θ2),   m2 l2²/3      ]],   c = m2 l1 l2 / 2,
    V = -g [(m1/2 + m2) l1 cos θ1 + (m2/2) l2 cos θ2],

so that Lagrange's equations are M θ̈ = Q with

    Q = [-c sin(θ1 - θ2) θ̇2² - (m1/2 + m2) g l1 sin θ1,
          c sin(θ1 - θ2) θ̇1² - (m2/2) g l2 sin θ2].

The lower tip is at x = l1 sin θ1 + l2 sin θ2; the wall x = wall_x stops it,
the admissible side being where the tip starts. At an impact (found by root
finding on the gap) Newton's law in minimal coordinates gives the jump
M (θ̇⁺ - θ̇⁻) = Wᵀ Λ with W θ̇⁺ = -e W θ̇⁻, W = [l1 cos θ1, l2 cos θ2] the
tip's x-Jacobian and Λ the wall's impulse [N s].
"""

from __future__ import annotations

import math

import numpy as np

from . import _custom_types  # noqa: F401  (float64 on from the moment the module loads, as in every numerical module)


def _mass(args, th1, th2):
    """M(θ) (2, 2) [kg m²] of the two rods; ``args`` = [m1, m2, l1, l2, g, wall_x, side]."""
    import jax.numpy as jnp

    m1, m2, l1, l2 = args[0], args[1], args[2], args[3]
    c = 0.5 * m2 * l1 * l2 * jnp.cos(th1 - th2)
    return jnp.stack([jnp.stack([(m1 / 3.0 + m2) * l1**2, c]), jnp.stack([c, m2 * l2**2 / 3.0])])


def _rhs(t, y, args):
    """d/dt [θ1, θ2, θ̇1, θ̇2] of the rods between impacts (Lagrange's equations)."""
    import jax.numpy as jnp

    m1, m2, l1, l2, g = args[0], args[1], args[2], args[3], args[4]
    th1, th2, w1, w2 = y
    c, s = 0.5 * m2 * l1 * l2, jnp.sin(th1 - th2)
    Q = jnp.stack([-c * s * w2**2 - (0.5 * m1 + m2) * g * l1 * jnp.sin(th1),
                   c * s * w1**2 - 0.5 * m2 * g * l2 * jnp.sin(th2)])
    acc = jnp.linalg.solve(_mass(args, th1, th2), Q)
    return jnp.stack([w1, w2, acc[0], acc[1]])


def _gap(t, y, args, **kwargs):
    """side (x_tip - wall_x) [m]."""
    import jax.numpy as jnp

    l1, l2, wall_x, side = args[2], args[3], args[5], args[6]
    return side * (l1 * jnp.sin(y[0]) + l2 * jnp.sin(y[1]) - wall_x)


def double_pendulum_energy(theta1, theta2, omega1, omega2, m1: float, m2: float, l1: float, l2: float,
                           gravity: float):
    """Kinetic + gravitational energy [J] of the rods (arrays of any one shape), zero
    potential at the pivot's height."""
    th1, th2, w1, w2 = (np.asarray(a, dtype=float) for a in (theta1, theta2, omega1, omega2))
    kinetic = 0.5 * ((m1 / 3.0 + m2) * l1**2 * w1**2 + m2 * l2**2 / 3.0 * w2**2
                     + m2 * l1 * l2 * np.cos(th1 - th2) * w1 * w2)
    potential = -gravity * ((0.5 * m1 + m2) * l1 * np.cos(th1) + 0.5 * m2 * l2 * np.cos(th2))
    return kinetic + potential


def double_pendulum_impact(th1: float, th2: float, w: np.ndarray, m1: float, m2: float, l1: float, l2: float,
                           e: float) -> tuple[np.ndarray, float]:
    """Newton's impact law at the tip in minimal coordinates: ``(θ̇⁺ (2,), Λ [N s])``
    from θ̇⁻ = ``w`` (2,) [rad/s] at the angles ``th1``, ``th2`` [rad]."""
    c = 0.5 * m2 * l1 * l2 * math.cos(th1 - th2)
    mass = np.array([[(m1 / 3.0 + m2) * l1**2, c], [c, m2 * l2**2 / 3.0]])
    W = np.array([l1 * math.cos(th1), l2 * math.cos(th2)])
    minv_w = np.linalg.solve(mass, W)
    impulse = -(1.0 + e) * float(W @ w) / float(W @ minv_w)
    return w + impulse * minv_w, impulse


def double_pendulum(t, m1: float, m2: float, l1: float, l2: float, gravity: float, theta1: float, theta2: float,
                    omega1: float, omega2: float, wall_x: float, e: float, rtol: float = 1e-12,
                    max_impacts: int = 1000):
    """Event-driven reference of the double pendulum of rods against a wall.

    Between impacts Lagrange's equations in θ1, θ2 (module docstring) are
    integrated by diffrax (Dopri8, tolerances ``rtol``); an impact is the root
    of the tip's gap (Newton root finding), where :func:`double_pendulum_impact`
    applies Newton's law. The parameters travel as arguments, so repeated
    calls compile once. Isolated impacts only: a tip that comes to rest on the
    wall (e = 0, or impacts accumulating) raises ``ValueError`` after
    ``max_impacts``.

    Args:
        t: times (K,) [s], from 0; masses [kg], lengths [m], gravity [m/s²]
            (along -y); initial angles [rad] and angular velocities [rad/s];
            wall_x [m]; e in [0, 1].

    Returns:
        ((θ1, θ2, θ̇1, θ̇2), impacts): the angles [rad] and angular velocities
        [rad/s] at the times ``t`` (right limits), each (K,), and one row per
        impact: (instant [s], tip x-velocity before, after [m/s], impulse [N s]).
    """
    import diffrax
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    t = np.asarray(t, dtype=float)
    x_tip = l1 * math.sin(theta1) + l2 * math.sin(theta2)
    side = float(np.sign(x_tip - wall_x))
    args = jnp.array([m1, m2, l1, l2, gravity, wall_x, side])
    term = diffrax.ODETerm(_rhs)
    event = diffrax.Event(_gap, root_finder=optx.Newton(rtol=1e-12, atol=1e-13))
    controller = diffrax.PIDController(rtol=rtol, atol=rtol)
    out = np.empty((t.size, 4))
    t0, y0 = 0.0, jnp.array([theta1, theta2, omega1, omega2], dtype=float)
    impacts: list[tuple[float, float, float, float]] = []
    t_end = float(t.max(initial=0.0))
    while True:
        sol = diffrax.diffeqsolve(term, diffrax.Dopri8(), jnp.asarray(t0), jnp.asarray(t_end), jnp.asarray(1e-3),
                                  y0, args=args, stepsize_controller=controller,
                                  saveat=diffrax.SaveAt(dense=True, t1=True), event=event, max_steps=100_000,
                                  throw=False)
        if not (bool(sol.result == diffrax.RESULTS.successful) or bool(sol.event_mask)):
            raise ValueError(f"the reference stops at t = {t0:.6g} s ({sol.result}): after an impact the tip stays "
                             "on the wall (e = 0, or impacts accumulating), which this reference of isolated "
                             "impacts does not describe")
        t1 = float(sol.ts[-1])
        start = impacts[-1][0] if impacts else t0
        inside = (t >= start) & (t <= t1)
        values = np.asarray(jax.vmap(sol.evaluate)(jnp.clip(jnp.asarray(t), t0, t1)))  # one shape: one compile
        out[inside] = values[inside]
        if t1 >= t_end or not sol.event_mask:
            break
        if len(impacts) >= max_impacts:
            raise ValueError(f"{max_impacts} impacts by t = {t1:.6g} s: the tip comes to rest on the wall, "
                             "which this reference of isolated impacts does not describe")
        th1, th2, w1, w2 = (float(a) for a in np.asarray(sol.ys[-1]))
        W = np.array([l1 * math.cos(th1), l2 * math.cos(th2)])
        after, impulse = double_pendulum_impact(th1, th2, np.array([w1, w2]), m1, m2, l1, l2, e)
        impacts.append((t1, float(W @ [w1, w2]), float(W @ after), impulse))
        # leave the wall by a Taylor step of 1 us (error ~1e-18) so that the
        # next segment does not start on the event surface
        y1 = jnp.array([th1, th2, after[0], after[1]])
        dt = 1e-6
        acc = _rhs(t1, y1, args)[2:]
        t0 = t1 + dt
        y0 = jnp.concatenate([y1[:2] + dt * y1[2:] + 0.5 * dt**2 * acc, y1[2:] + dt * acc])
    return (out[:, 0], out[:, 1], out[:, 2], out[:, 3]), np.asarray(impacts).reshape(-1, 4)
