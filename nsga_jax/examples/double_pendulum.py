"""A double pendulum striking a wall: a complete user model and scene.

This file is a worked example of writing one's own model and scene (see
``docs/own-model.md``). Give its path wherever a scene name is taken::

    nsga-jax run examples/double_pendulum.py --t-end 2
    nsga-jax sweep examples/double_pendulum.py --grid 'e=0.2;0.8'
    nsga-jax convergence examples/double_pendulum.py --h 4e-3,2e-3 --ref-h 5e-4
    nsga-jax identify examples/double_pendulum.py --params e --synthetic --true e=0.5 --initial e=0.6

    scene = nsga_jax.load_scene("examples/double_pendulum.py", {"e": 0.3})
    sol = nsga_jax.integrate(scene.model, nsga_jax.DS(), 0.0, 0.5, 1e-3, scene.q0, scene.v0,
                             adjoint=nsga_jax.ImpactTimeAdjoint())  # differentiable; sees the impact instant move

The system
----------
Two point masses m1, m2 [kg] in the vertical (x, y) plane, y upward [m]. A
massless rigid rod of length l1 [m] joins a fixed pivot at the origin to
mass 1, a second rod of length l2 [m] joins mass 1 to mass 2. Gravity g
[m/s²] acts along -y. A vertical wall at x = wall_x [m] stops the lower
mass (mass 2) with Newton's impact law, restitution e in [0, 1]; the upper
mass never reaches the wall (the scene's ``check`` asks |wall_x| >= l1), and
the rods are lines that the wall does not see.

Coordinates q = [x1, y1, x2, y2] [m] (Cartesian, so the mass matrix is
constant and the rods are nonlinear bilateral constraints), velocities
v = dq/dt [m/s]. The equations of motion (measure differential form of the
paper's eq. 1) are

    M dv - g_q(q)^T di = f dt,        M = diag(m1, m1, m2, m2),
                                      f = [0, -m1 g, 0, -m2 g],

    g^B_1(q) = (x1² + y1² - l1²) / (2 l1)                 = 0  (rod 1),
    g^B_2(q) = ((x2 - x1)² + (y2 - y1)² - l2²) / (2 l2)   = 0  (rod 2),
    g^U(q)   = side (x2 - wall_x) >= 0                         (wall),
    Newton's law: g_q^U v⁺ = -e g_q^U v⁻ when mass 2 hits the wall,

with ``side = -sign(wall_x)`` (+1 for a wall left of the pivot, -1 for one
on its right: the pivot is on the admissible side). Each rod constraint is
divided by 2 l so that it measures a length (≈ |r| - l near the constraint)
and its gradient is the unit vector along the rod: the multipliers are the
rod tensions [N] and the wall's multiplier is its normal impulse [N s].

Between impacts this is the double pendulum of the textbooks; in the angles
θ1, θ2 from the downward vertical (x1 = l1 sin θ1, y1 = -l1 cos θ1,
x2 = x1 + l2 sin θ2, y2 = y1 - l2 cos θ2) its Lagrange equations are

    (m1 + m2) l1 θ1'' + m2 l2 cos(θ1 - θ2) θ2'' = -m2 l2 sin(θ1 - θ2) θ2'² - (m1 + m2) g sin θ1,
    l1 cos(θ1 - θ2) θ1'' + l2 θ2''             =  l1 sin(θ1 - θ2) θ1'² - g sin θ2,

which the tests integrate with an ODE solver as an independent reference.

The defaults throw the pendulum (θ1 = 0.8 rad, θ2 = 1.2 rad, both rods
turning clockwise at 4 rad/s) towards a wall at x = -0.55 m: the lower mass
strikes it at t ≈ 0.32 s and again at t ≈ 1.63 s, within the default
t_end = 2 s.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp

import nsga_jax
from nsga_jax.scenes import POSITIVE, UNIT_INTERVAL, Param, Range, SceneSpec, register


def as_float(x) -> jax.Array:
    """Field converter: numbers become float arrays, i.e. pytree leaves that
    ``jit`` traces (changing them never recompiles) and ``grad`` can reach."""
    return jnp.asarray(x, dtype=float)


# ---------------------------------------------------------------- the model


class DoublePendulum(nsga_jax.Model):
    """Two point masses on rigid rods (pivot at the origin), and a wall for the lower mass.

    Coordinates q = [x1, y1, x2, y2] [m] (y upward); two nonlinear bilateral
    rod constraints and one unilateral wall constraint on mass 2 (see the
    module docstring for the equations).

    Fields (pytree leaves, differentiable): m1, m2 [kg]; l1, l2 [m]; gravity
    [m/s²]; wall_x [m]; side (±1, the admissible side of the wall); e
    (restitution, in [0, 1]).
    """

    m1: jax.Array = eqx.field(converter=as_float)
    m2: jax.Array = eqx.field(converter=as_float)
    l1: jax.Array = eqx.field(converter=as_float)
    l2: jax.Array = eqx.field(converter=as_float)
    gravity: jax.Array = eqx.field(converter=as_float)
    wall_x: jax.Array = eqx.field(converter=as_float)
    side: jax.Array = eqx.field(converter=as_float)
    e: jax.Array = eqx.field(converter=as_float)

    # Checked with concrete values by nsga_jax.simulate before anything is traced.
    ranges = {"m1": POSITIVE, "m2": POSITIVE, "l1": POSITIVE, "l2": POSITIVE,
              "side": Range(-1.0, 1.0), "e": UNIT_INTERVAL}

    # Sizes and structure: plain class values, known when the step is traced.
    n_dof = 4
    n_bilateral = 2
    n_unilateral = 1
    constant_mass = True             # M = diag(m1, m1, m2, m2) does not depend on q
    linear_force = True              # f is constant (gravity): K = C = 0
    velocity_dependent_force = False  # f does not depend on v
    linear_constraints = False       # the rods are quadratic in q (the wall is affine)

    @property
    def mbar(self) -> jax.Array:
        """Characteristic mass m̄ [kg] scaling the multipliers: the mean of m1 and m2."""
        return 0.5 * (self.m1 + self.m2)

    def _masses(self, dtype) -> jax.Array:
        """[m1, m1, m2, m2] [kg], shape (4,)."""
        return jnp.stack([self.m1, self.m1, self.m2, self.m2]).astype(dtype)

    def mass(self, q: jax.Array) -> jax.Array:
        """M = diag(m1, m1, m2, m2) [kg], shape (4, 4)."""
        return jnp.diag(self._masses(q.dtype))

    def mass_product(self, q: jax.Array, x: jax.Array) -> jax.Array:
        """M x, shape (4,), without forming M."""
        return self._masses(x.dtype) * x

    def force(self, q: jax.Array, v: jax.Array, t: jax.Array) -> jax.Array:
        """Gravity [0, -m1 g, 0, -m2 g] [N], shape (4,)."""
        zero = jnp.zeros(())
        return jnp.stack([zero, -self.m1 * self.gravity, zero, -self.m2 * self.gravity]).astype(q.dtype)

    def bilateral(self, q: jax.Array) -> jax.Array:
        """Rod constraints [(|r1|² - l1²)/(2 l1), (|r2 - r1|² - l2²)/(2 l2)] [m], shape (2,)."""
        x1, y1, x2, y2 = q
        rod1 = (x1**2 + y1**2 - self.l1**2) / (2.0 * self.l1)
        rod2 = ((x2 - x1) ** 2 + (y2 - y1) ** 2 - self.l2**2) / (2.0 * self.l2)
        return jnp.stack([rod1, rod2])

    def unilateral(self, q: jax.Array) -> jax.Array:
        """Gap of mass 2 to the wall, side (x2 - wall_x) [m], shape (1,)."""
        return (self.side * (q[2] - self.wall_x))[None]

    @property
    def restitution(self) -> jax.Array:
        """Newton restitution coefficient at the wall, shape (1,)."""
        return self.e[None]

    def energy(self, q: jax.Array, v: jax.Array) -> jax.Array:
        """Kinetic + potential energy [J] (zero potential at the pivot height)."""
        kinetic = 0.5 * jnp.sum(self._masses(v.dtype) * v**2)
        return kinetic + self.gravity * (self.m1 * q[1] + self.m2 * q[3])


# ---------------------------------------------------------------- the scene

PARAMETERS = {
    "m1": Param(1.0, "upper mass", "kg", lo=0.0, lo_open=True),
    "m2": Param(1.0, "lower mass (the one that strikes the wall)", "kg", lo=0.0, lo_open=True),
    "l1": Param(0.5, "length of the upper rod (pivot to mass 1)", "m", lo=0.0, lo_open=True),
    "l2": Param(0.5, "length of the lower rod (mass 1 to mass 2)", "m", lo=0.0, lo_open=True),
    "gravity": Param(9.81, "gravitational acceleration (along -y)", "m/s^2", lo=0.0),
    "theta1": Param(0.8, "initial angle of rod 1 from the downward vertical, positive towards +x", "rad",
                    lo=-math.pi, hi=math.pi),
    "theta2": Param(1.2, "initial angle of rod 2 from the downward vertical, positive towards +x", "rad",
                    lo=-math.pi, hi=math.pi),
    "omega1": Param(-4.0, "initial angular velocity of rod 1 (positive: counter-clockwise)", "rad/s"),
    "omega2": Param(-4.0, "initial angular velocity of rod 2 (positive: counter-clockwise)", "rad/s"),
    "wall_x": Param(-0.55, "x position of the vertical wall; the pivot's side is the admissible one, "
                    "and |wall_x| >= l1 (the wall acts on the lower mass only)", "m"),
    "e": Param(0.7, "Newton restitution coefficient at the wall", lo=0.0, hi=1.0),
}


def _positions(p):
    """Initial [x1, y1, x2, y2] [m] from the angles (works on floats and on traced arrays)."""
    l1, l2, th1, th2 = p["l1"], p["l2"], p["theta1"], p["theta2"]
    x1, y1 = l1 * jnp.sin(th1), -l1 * jnp.cos(th1)
    return jnp.stack([x1, y1, x1 + l2 * jnp.sin(th2), y1 - l2 * jnp.cos(th2)])


def _velocities(p):
    """Initial [vx1, vy1, vx2, vy2] [m/s] from the angles and angular velocities."""
    l1, l2, th1, th2 = p["l1"], p["l2"], p["theta1"], p["theta2"]
    vx1, vy1 = l1 * p["omega1"] * jnp.cos(th1), l1 * p["omega1"] * jnp.sin(th1)
    return jnp.stack([vx1, vy1, vx1 + l2 * p["omega2"] * jnp.cos(th2), vy1 + l2 * p["omega2"] * jnp.sin(th2)])


def _side(wall_x: float) -> float:
    """The admissible side of the wall, ±1: the pivot's (x = 0)."""
    return -math.copysign(1.0, wall_x)


def check(p):
    """Refuse setups the model cannot describe, before anything is compiled:
    a wall the upper mass could reach, and a lower mass starting on or beyond
    the wall."""
    if abs(p["wall_x"]) < p["l1"]:
        raise nsga_jax.ConfigError(
            f"wall_x [m] = {p['wall_x']!r}: the upper mass (rod length l1 = {p['l1']!r}) could reach the wall, "
            "which acts on the lower mass only; put the wall at |wall_x| >= l1"
        )
    x2 = p["l1"] * math.sin(p["theta1"]) + p["l2"] * math.sin(p["theta2"])
    gap = _side(p["wall_x"]) * (x2 - p["wall_x"])
    if gap <= 1e-12 * max(1.0, p["l1"] + p["l2"]):
        where = "on" if abs(gap) <= 1e-12 * max(1.0, p["l1"] + p["l2"]) else "beyond"
        raise nsga_jax.ConfigError(
            f"theta1, theta2: the lower mass starts {where} the wall (x2 = {x2:.6g} m, wall_x = {p['wall_x']!r} m); "
            "change theta1, theta2 or wall_x"
        )


def make(p, concrete):
    """``(model, q0, v0, observables)``, JAX-traceable in the float parameters ``p``;
    the wall's side (structure) is read from the concrete values."""
    side = _side(concrete["wall_x"])
    model = DoublePendulum(m1=p["m1"], m2=p["m2"], l1=p["l1"], l2=p["l2"], gravity=p["gravity"],
                           wall_x=p["wall_x"], side=side, e=p["e"])
    q0, v0 = _positions(p), _velocities(p)

    def observables(sol):
        """Named observables, each (N+1,), from sol.q, sol.v, sol.impulse [N s] and sol.h [s]."""
        x1, y1, x2, y2 = (sol.q[:, i] for i in range(4))
        vx2, vy2 = sol.v[:, 2], sol.v[:, 3]
        kinetic = 0.5 * p["m1"] * (sol.v[:, 0] ** 2 + sol.v[:, 1] ** 2) + 0.5 * p["m2"] * (vx2**2 + vy2**2)
        return {
            "x2": x2, "y2": y2, "vx2": vx2, "vy2": vy2,          # lower mass [m], [m/s]
            "x1": x1, "y1": y1,                                  # upper mass [m]
            "gap": side * (x2 - p["wall_x"]),                    # distance to the wall [m]
            "rod1": jnp.hypot(x1, y1) - p["l1"],                 # rod length errors [m]
            "rod2": jnp.hypot(x2 - x1, y2 - y1) - p["l2"],
            "force": sol.impulse[:, 2] / sol.h,                  # wall force, mean over the step [N]
            "energy": kinetic + p["gravity"] * (p["m1"] * y1 + p["m2"] * y2),  # [J]
        }

    return model, q0, v0, observables


SPEC = register(
    SceneSpec(
        name="double_pendulum_masses",
        description="Double pendulum (two point masses, two rigid rods) whose lower mass strikes a wall",
        parameters=PARAMETERS,
        solver_defaults={"h": 1e-3, "t_end": 2.0},
        make=make,
        check=check,
        observables=("x2", "y2", "vx2", "vy2", "x1", "y1", "gap", "rod1", "rod2", "force", "energy"),
        error_observables=("x2", "vx2"),
        units={"x2": "m", "y2": "m", "vx2": "m/s", "vy2": "m/s", "x1": "m", "y1": "m", "gap": "m", "rod1": "m",
               "rod2": "m", "force": "N", "energy": "J"},
        plotted=("x2", "vx2", "gap", "force", "rod1", "rod2", "energy"),
    )
)
