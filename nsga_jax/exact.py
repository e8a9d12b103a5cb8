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
