"""Exact solutions used as references (eq. 52 errors, tests)."""

from __future__ import annotations

import numpy as np


def bouncing_ball_impacts(height: float, velocity: float, gravity: float, e: float, t_max: float):
    """Impact times and pre-impact speeds of a ball dropped on a floor.

    Args:
        height: initial height [m] (>= 0); velocity: initial vertical velocity
            [m/s], upward positive; gravity [m/s²] (> 0); e: restitution in [0, 1];
        t_max: last time of interest [s].

    Returns:
        (times, speeds, t_rest): impact instants up to t_max, the impact speeds
        (downward, positive), and the instant after which the ball rests on the
        floor (``inf`` if it never does before t_max; the accumulation point of
        the impacts when e < 1).
    """
    times, speeds = [], []
    speed = np.sqrt(velocity**2 + 2.0 * gravity * height)
    t = (velocity + speed) / gravity
    if e < 1.0 and speed > 0.0:
        t_rest = t + 2.0 * e * speed / (gravity * (1.0 - e))
    else:
        t_rest = 0.0 if speed == 0.0 else np.inf
    while t <= t_max and speed > 0.0:
        times.append(t)
        speeds.append(speed)
        speed = e * speed
        t = t + 2.0 * speed / gravity
        if speed < 1e-12 * (1.0 + speeds[0]):
            break
    return np.asarray(times), np.asarray(speeds), t_rest


def bouncing_ball(t, height: float, velocity: float, gravity: float, e: float):
    """Exact height z(t) [m] and velocity v(t) [m/s] (right limit) of the bouncing ball.

    Between impacts the ball flies freely; at an impact v+ = -e v-; after the
    accumulation point of the impacts (e < 1) it rests at z = 0.
    """
    t = np.asarray(t, dtype=float)
    times, speeds, t_rest = bouncing_ball_impacts(height, velocity, gravity, e, float(t.max(initial=0.0)))
    # flight k starts at t_k with z = 0 and upward speed e * speed_k (k >= 1),
    # flight 0 starts at t = 0 from the initial state.
    starts = np.concatenate([[0.0], times])
    z_start = np.concatenate([[height], np.zeros(len(times))])
    v_start = np.concatenate([[velocity], e * speeds])
    k = np.searchsorted(starts, t, side="right") - 1
    s = t - starts[k]
    z = z_start[k] + v_start[k] * s - 0.5 * gravity * s**2
    v = v_start[k] - gravity * s
    resting = t >= t_rest
    z = np.where(resting, 0.0, np.maximum(z, 0.0))
    v = np.where(resting, 0.0, v)
    return z, v


def _pendulum_rhs(t, y, args):
    import jax.numpy as jnp

    g_over_l = args[0]
    return jnp.stack([y[1], -g_over_l * jnp.sin(y[0])])


def _pendulum_wall_gap(t, y, args, **kwargs):
    import jax.numpy as jnp

    _, length, wall_x, side = args
    return side * (length * jnp.sin(y[0]) - wall_x)


def rigid_pendulum(t, length: float, gravity: float, angle: float, omega: float, wall_x: float, e: float,
                   rtol: float = 1e-12):
    """Event-driven reference of the rigid pendulum against a vertical wall.

    The angle φ from the downward vertical obeys φ'' = -(g/L) sin φ between
    impacts (diffrax, Dopri8, tolerances ``rtol``); the mass hits the wall when
    ``L sin φ = wall_x`` (the instant found by Newton root finding), where
    Newton's law on the wall's normal velocity L cos φ φ' gives φ'⁺ = -e φ'⁻.
    The parameters travel as arguments, so repeated calls compile once.

    Returns:
        (x, y, vx, vy) at the times ``t`` [m, m/s], and the impact instants.
    """
    import diffrax
    import jax
    import jax.numpy as jnp
    import optimistix as optx

    t = np.asarray(t, dtype=float)
    side = float(np.sign(length * np.sin(angle) - wall_x))
    args = jnp.array([gravity / length, length, wall_x, side])
    term = diffrax.ODETerm(_pendulum_rhs)
    event = diffrax.Event(_pendulum_wall_gap, root_finder=optx.Newton(rtol=1e-12, atol=1e-13))
    controller = diffrax.PIDController(rtol=rtol, atol=rtol)
    phi = np.empty_like(t)
    dphi = np.empty_like(t)
    t0, y0 = 0.0, jnp.array([angle, omega])
    impacts: list[float] = []
    t_end = float(t.max(initial=0.0))
    while t0 < t_end:
        sol = diffrax.diffeqsolve(term, diffrax.Dopri8(), jnp.asarray(t0), jnp.asarray(t_end), jnp.asarray(1e-3),
                                  y0, args=args,
                                  stepsize_controller=controller, saveat=diffrax.SaveAt(dense=True, t1=True),
                                  event=event, max_steps=100_000)
        t1 = float(sol.ts[-1])
        start = impacts[-1] if impacts else t0
        inside = (t >= start) & (t <= t1)
        values = np.asarray(jax.vmap(sol.evaluate)(jnp.clip(jnp.asarray(t), t0, t1)))  # one shape: one compile
        phi[inside], dphi[inside] = values[inside, 0], values[inside, 1]
        if t1 >= t_end or not sol.event_mask:
            break
        impacts.append(t1)
        phi1, dphi1 = float(sol.ys[-1][0]), -e * float(sol.ys[-1][1])
        # leave the wall by a Taylor step of 1 us (error 1e-18) so that the next
        # segment does not start on the event surface
        dt, acc = 1e-6, -(gravity / length) * np.sin(phi1)
        t0, y0 = t1 + dt, jnp.array([phi1 + dt * dphi1 + 0.5 * dt**2 * acc, dphi1 + dt * acc])
    x, y = length * np.sin(phi), -length * np.cos(phi)
    vx, vy = length * np.cos(phi) * dphi, length * np.sin(phi) * dphi
    return (x, y, vx, vy), np.asarray(impacts)


def newtons_cradle_collisions(x0, v0, mass, radius: float, e: float, t_max: float, max_collisions: int = 10_000):
    """The sequence of binary collisions of balls on a frictionless line.

    Between collisions every ball flies at constant velocity; two neighbours
    collide when their gap ``x_{i+1} - x_i - 2 radius`` closes, and Newton's
    law on their relative velocity with momentum conservation gives

        v_i⁺     = v_i⁻     - m_{i+1} (1 + e) (v_i⁻ - v_{i+1}⁻) / (m_i + m_{i+1}),
        v_{i+1}⁺ = v_{i+1}⁻ + m_i     (1 + e) (v_i⁻ - v_{i+1}⁻) / (m_i + m_{i+1}).

    With every gap > 0 no two collisions are simultaneous (for equal masses
    and e = 1 the velocities are exchanged, and the last ball leaves with the
    first one's velocity).

    Args:
        x0: initial centres (N,) [m], increasing; v0: initial velocities (N,) [m/s];
        mass: each ball's mass [kg], scalar or (N,); radius [m]; e: restitution
            in [0, 1]; t_max: last time of interest [s].

    Returns:
        (times, states): the collision instants (K,) [s] in order, and the
        state after each as ``(x, v)`` arrays of shape (K + 1, N) — row 0 the
        initial state, row k the centres at collision k and the velocities
        just after it.
    """
    x = np.array(x0, dtype=float)
    v = np.array(v0, dtype=float)
    m = np.broadcast_to(np.asarray(mass, dtype=float), x.shape)
    t, times, xs, vs = 0.0, [], [x.copy()], [v.copy()]
    for _ in range(max_collisions):
        closing = v[:-1] - v[1:]
        gaps = np.maximum(x[1:] - x[:-1] - 2.0 * radius, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            dt = np.where(closing > 0.0, gaps / closing, np.inf)
        i = int(np.argmin(dt))
        if not np.isfinite(dt[i]) or t + dt[i] > t_max:
            break
        t += float(dt[i])
        x = x + dt[i] * v
        x[i + 1] = x[i] + 2.0 * radius  # exactly in contact (no round-off overlap)
        p = (1.0 + e) * closing[i] / (m[i] + m[i + 1])
        v[i], v[i + 1] = v[i] - m[i + 1] * p, v[i + 1] + m[i] * p
        times.append(t)
        xs.append(x.copy())
        vs.append(v.copy())
    return np.asarray(times), (np.asarray(xs), np.asarray(vs))


def newtons_cradle(t, x0, v0, mass, radius: float, e: float):
    """Exact centres x(t) [m] and velocities v(t) [m/s] (right limits) of the
    balls of :func:`newtons_cradle_collisions`, each of shape (len(t), N)."""
    t = np.asarray(t, dtype=float)
    times, (xs, vs) = newtons_cradle_collisions(x0, v0, mass, radius, e, float(t.max(initial=0.0)))
    starts = np.concatenate([[0.0], times])
    k = np.searchsorted(starts, t, side="right") - 1
    k = np.maximum(k, 0)
    s = (t - starts[k])[:, None]
    return xs[k] + s * vs[k], vs[k]


def incline(t, angle: float, mu: float, gravity: float, velocity: float = 0.0):
    """Exact distance s(t) [m] and velocity ds(t) [m/s] down a plane tilted by
    ``angle`` [rad] of a block sliding with Coulomb friction ``mu`` (>= 0),
    both measured along the slope, downhill positive, from s(0) = 0,
    ds(0) = ``velocity``.

    Sliding down (ds > 0) the block accelerates at a_down = g (sin - mu cos),
    sliding up (ds < 0) at a_up = g (sin + mu cos) (downhill, slowing it); at rest it stays where
    tan(angle) <= mu and leaves downhill at a_down otherwise. A block sliding
    down with a_down < 0 stops at t = ds(0) / |a_down| and stays; one sent up
    stops at t = -ds(0) / a_up and then rests or slides down.
    """
    t = np.asarray(t, dtype=float)
    sin, cos = np.sin(angle), np.cos(angle)
    a_down, a_up = gravity * (sin - mu * cos), gravity * (sin + mu * cos)
    sticks = np.tan(angle) <= mu

    def from_rest(tau):
        a = 0.0 if sticks else a_down
        return 0.5 * a * tau**2, a * tau

    if velocity > 0.0 and a_down < 0.0:  # decelerates downhill to rest, then sticks (tan < mu)
        t_stop = velocity / -a_down
        tau = np.minimum(t, t_stop)
        return velocity * tau + 0.5 * a_down * tau**2, np.where(t < t_stop, velocity + a_down * tau, 0.0)
    if velocity > 0.0 or (velocity == 0.0 and not sticks):
        return velocity * t + 0.5 * a_down * t**2, velocity + a_down * t
    if velocity == 0.0:
        return np.zeros_like(t), np.zeros_like(t)
    t_stop = -velocity / a_up  # velocity < 0: slides up, decelerating, to rest at s_stop
    s_stop = 0.5 * velocity * t_stop
    tau = t - t_stop
    s_rest, v_rest = from_rest(np.maximum(tau, 0.0))
    up = t < t_stop
    return (np.where(up, velocity * t + 0.5 * a_up * t**2, s_stop + s_rest),
            np.where(up, velocity + a_up * t, v_rest))


def housner_ratio(width: float, height: float) -> float:
    """Housner's ratio ω+/ω- of the angular velocities after and before the
    impact of a rigid rectangular block (``width`` b, ``height`` h [m]) rocking
    on a floor, the landing corner sticking without rebound:
    1 - (3/2) sin²α with α = atan(b/h) the slenderness angle (from the
    conservation of the angular momentum about the landing corner, the
    block's inertia about a corner being I_O = (4/3) m R², R = ½ √(b² + h²))."""
    alpha = np.arctan2(width, height)
    return float(1.0 - 1.5 * np.sin(alpha) ** 2)


def rocking_impacts(width: float, height: float, gravity: float, tilt: float, n: int):
    """Angular velocities [rad/s] (magnitudes) of a rocking block just before
    and just after each of its first ``n`` impacts, released from rest at
    ``tilt`` [rad] (0 < tilt < α) on one corner.

    On a corner the block obeys θ'' = -p² sin(α sgn θ - θ), p² = m g R / I_O =
    3 g / (4 R): energy ½ θ'² - p² cos(α - |θ|) is kept between impacts, so
    the block lands with |ω-|² = 2 p² (cos(α - tilt) - cos α) and each impact
    multiplies |ω| by :func:`housner_ratio`; after an impact it swings up and
    lands back with the same speed. Returns (before (n,), after (n,)).
    """
    alpha = np.arctan2(width, height)
    p2 = 3.0 * gravity / (2.0 * np.hypot(width, height))
    ratio = housner_ratio(width, height)
    first = np.sqrt(2.0 * p2 * (np.cos(alpha - tilt) - np.cos(alpha)))
    before = first * np.abs(ratio) ** np.arange(n)
    return before, before * abs(ratio)


def _swing_time(alpha: float, p2: float, apex: float) -> float:
    """Time [s] a block rocking on a corner takes from flat (θ = 0) to its
    apex θ = ``apex`` (or back): T = ∫ dθ / θ' with
    θ'² = 2 p² (cos(α - apex) - cos(α - θ)), written with φ = α - θ =
    φ_m + u² (φ_m = α - apex) so that the integrand is smooth at the apex,
    and taken by 64-point Gauss–Legendre quadrature."""
    phi_m = alpha - apex
    nodes, weights = np.polynomial.legendre.leggauss(64)
    top = np.sqrt(apex)
    u = 0.5 * top * (nodes + 1.0)
    drop = 2.0 * np.sin(phi_m + 0.5 * u**2) * np.sin(0.5 * u**2)  # cos φ_m - cos(φ_m + u²), no cancellation
    integrand = 2.0 * u / np.sqrt(2.0 * p2 * drop)
    return float(0.5 * top * np.sum(weights * integrand))


def rocking_impact_times(width: float, height: float, gravity: float, tilt: float, n: int) -> np.ndarray:
    """Times [s] of the first ``n`` impacts of a rocking block released from
    rest at ``tilt`` [rad] (0 < |tilt| < α) on one corner
    (:func:`rocking_impacts`): the fall from the tilt to flat, then, after
    impact k, a swing up to the apex where ½ ω_k+² = p² (cos(α - θ_max) -
    cos α) and back. The intervals shrink with the speeds, so the impacts
    accumulate (a Zeno point) at a finite time; a time-stepping run resolves
    them while the interval is several steps long."""
    alpha = np.arctan2(width, height)
    p2 = 3.0 * gravity / (2.0 * np.hypot(width, height))
    _, after = rocking_impacts(width, height, gravity, abs(tilt), n)
    rise = after**2 / (2.0 * p2)  # cos(α - θ_max) - cos α = 2 sin(α - θ_max/2) sin(θ_max/2), solved by Newton
    apexes = rise / np.sin(alpha)
    for _ in range(50):
        residual = 2.0 * np.sin(alpha - 0.5 * apexes) * np.sin(0.5 * apexes) - rise
        apexes = apexes - residual / np.sin(alpha - apexes)
    swings = [2.0 * _swing_time(alpha, p2, a) for a in apexes[:-1]]
    return _swing_time(alpha, p2, abs(tilt)) + np.concatenate([[0.0], np.cumsum(swings)])


def landings(theta: np.ndarray) -> np.ndarray:
    """Indices of the records where a rocking angle θ (rows,) [rad] has
    changed sign since its last nonzero value: the rocking block's landings
    (|θ| < 1e-12 counts as flat, not as a sign)."""
    theta = np.asarray(theta)
    sign = np.sign(np.where(np.abs(theta) < 1e-12, 0.0, theta))
    nonzero = np.nonzero(sign)[0]
    return nonzero[1:][sign[nonzero[1:]] != sign[nonzero[:-1]]]


def resolvable_impacts(exact: np.ndarray, h: float, steps: int = 10) -> np.ndarray:
    """The impacts of ``exact`` (times [s], increasing) that a run of step
    ``h`` [s] can resolve: those up to the first that comes less than
    ``steps`` steps after the one before (the accumulating impacts of a
    Zeno sequence come closer and closer)."""
    exact = np.asarray(exact, float)
    close = np.diff(exact, prepend=0.0) < steps * h
    return exact[: int(np.argmax(close))] if close.any() else exact


def match_impacts(measured: np.ndarray, exact: np.ndarray, h: float, steps: int = 10) -> dict:
    """Pair a run's impact times with the exact ones, one to one, while the
    exact ones are resolvable (:func:`resolvable_impacts`).

    Each resolvable exact impact t_k owns the window from halfway to the
    exact impact before it to halfway to the one after it (the windows tile
    the time axis up to the last resolvable one's). An exact impact is
    *matched* when exactly one of the run's impacts falls in its window; the
    run's impacts in the windows beyond one per window, or in a window
    whose exact impact is matched by none, are *extra*. A run that has
    exactly the exact solution's impacts while they are resolvable has
    ``matched == resolvable`` and ``extra == 0``.

    Args:
        measured: the run's impact times [s], shape (m,).
        exact: the exact impact times [s], increasing, shape (n,), longer
            than the resolvable part (the window of the last resolvable one
            ends halfway to the next).
        h: the run's step [s].
        steps: resolvable means at least this many steps after the last.

    Returns:
        ``{"resolvable", "matched", "extra", "last" [s], "max_error" [s]}``:
        the counts, the last resolvable exact time and the largest
        |measured - exact| over the matched impacts (NaN if none).

    Raises:
        ValueError: fewer than two exact impacts are resolvable at ``h``.
    """
    exact = np.asarray(exact, float)
    measured = np.asarray(measured, float)
    resolvable = resolvable_impacts(exact, h, steps)
    k = len(resolvable)
    if k < 2:
        raise ValueError(f"{k} resolvable exact impact(s) at h = {h:g} s: nothing to pair the run's with")
    after = exact[k] if k < len(exact) else resolvable[-1] + (resolvable[-1] - resolvable[-2])
    edges = np.concatenate([[0.0], 0.5 * (resolvable[1:] + resolvable[:-1]), [0.5 * (resolvable[-1] + after)]])
    inside = measured[measured < edges[-1]]
    counts = np.histogram(inside, bins=edges)[0]
    one = counts == 1
    window = np.clip(np.searchsorted(edges, inside, side="right") - 1, 0, k - 1)
    errors = np.abs(inside - resolvable[window])[one[window]]
    return {"resolvable": k, "matched": int(one.sum()), "extra": int(len(inside) - one.sum()),
            "last": float(resolvable[-1]), "max_error": float(errors.max()) if errors.size else float("nan")}
