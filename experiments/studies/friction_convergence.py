"""Coulomb friction against exact solutions: the sliding box's stopping distance
and time, the block on an incline, and the gradient of the sliding distance.

    python experiments/studies/friction_convergence.py

A box of mass m resting flat on a floor with friction coefficient mu, launched
horizontally at v0 [m/s], decelerates at mu g and stops at T = v0/(mu g) [s]
after d = v0²/(2 mu g) [m]. For each scheme and step h the table gives the
error of the distance d_h - d (the final displacement) and of the stopping
time t_h - T, where t_h is the first step time at which the sliding speed is
zero (so 0 <= t_h - T < h is the best a fixed grid can do); the observed order
is the least-squares slope of log |error| against log h. On an incline of
angle a with tan a > mu the block accelerates down the slope at
g (sin a - mu cos a); the table gives the velocity error at the last step
(t = floor(0.5/h) h), in the d_err columns. The stopping time's "order" is
not a convergence order: t_h - T is the distance from T to the next step
time, between 0 and h (the min/max columns give (t_h - T)/h), and erratic in h.
MJ on the 3D box fails steps at rest on four vertices (failed_steps), so
its rows are not converged results.

Gradient table: d(d)/d(mu) = -v0²/(2 mu² g) and d(d)/d(v0) = v0/(mu g)
against the gradient nsga_jax.integrate returns (DiscreteAdjoint and
ImpactTimeAdjoint) and central finite differences of the same discrete run.

At the stick-slip switch (v0 such that T is a step time for MJ, a half-step
time for DS) the switch table gives the distance and its gradient on both
sides.

Writes docs/results/friction/{convergence,gradients,switch}.{csv,md};
``python experiments/studies/friction_convergence.py switch`` runs one part.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import nsga_jax  # noqa: E402
from nsga_jax._elements.rigid_body import box_inertia, box_vertices  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._tables import write_csv  # noqa: E402
from nsga_jax.system import Gravity, PlaneContact, RigidBody2D, RigidBody3D, System  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

G, MU, V0 = 9.81, 0.3, 2.0
RESULTS = Path("docs/results/friction")
STEPS = (4e-3, 2.8e-3, 2e-3, 1.4e-3, 1e-3, 7e-4, 5e-4)
SCHEMES = {"DS": nsga_jax.DS(), "DSn": nsga_jax.DSn(), "CS": nsga_jax.CS(), "MJ": nsga_jax.MJ()}


def box_2d(v0=V0, mu=MU, angle=0.0):
    """A 0.2 m x 0.1 m box of 1 kg on its long face, on the floor through the
    origin with normal (-sin a, cos a), launched at v0 [m/s] along the floor."""
    n = jnp.stack([-jnp.sin(angle), jnp.cos(angle)])
    t = jnp.stack([jnp.cos(angle), jnp.sin(angle)])
    s = System(dim=2)
    s.add_body("box", RigidBody2D(1.0, (0.2**2 + 0.1**2) / 12, position=0.05 * n, angle=angle, velocity=v0 * t))
    s.add_contact("floor", PlaneContact("box", normal=n, origin=[0.0, 0.0], e=0.0,
                                        points=[[-0.1, -0.05], [0.1, -0.05]], mu=mu))
    s.add_force("g", Gravity([0.0, -G]))
    return s.model()


def box_3d(velocity, mu=MU):
    """A 0.2 x 0.1 x 0.1 m box of 1 kg resting on its four lower vertices,
    launched horizontally at ``velocity`` (3,) [m/s]."""
    sides = jnp.array([0.2, 0.1, 0.1])
    vertices = box_vertices(sides)
    s = System(dim=3)
    s.add_body("box", RigidBody3D(1.0, box_inertia(1.0, sides), position=[0.0, 0.0, 0.05], velocity=velocity))
    s.add_contact("floor", PlaneContact("box", normal=[0.0, 0.0, 1.0], origin=[0.0, 0.0, 0.0], e=0.0,
                                        points=vertices[np.asarray(vertices[:, 2]) < 0], mu=mu))
    s.add_force("g", Gravity([0.0, 0.0, -G]))
    return s.model()


def stop(model, scheme, h, t_end=1.2):
    """(distance [m], first step time at rest [s], failed steps) of a sliding box."""
    q0, v0 = model.initial_state()
    sol = nsga_jax.simulate(model, scheme, 0.0, t_end, h, q0, v0, throw=False)
    d = model.dim
    q, v, ts = np.asarray(sol.q), np.asarray(sol.v), np.asarray(sol.ts)
    speed = np.linalg.norm(v[:, :d - 1] if d == 2 else v[:, :2], axis=1)
    at_rest = int(np.argmax(speed <= 1e-9))
    distance = float(np.linalg.norm(q[-1, :d - 1 if d == 2 else 2] - q[0, :d - 1 if d == 2 else 2]))
    return distance, float(ts[at_rest]), len(sol.failed_steps)


def order(hs, errors) -> float:
    errors = np.abs(np.asarray(errors))
    ok = errors > 1e-14
    return float(np.polyfit(np.log(np.asarray(hs)[ok]), np.log(errors[ok]), 1)[0]) if ok.sum() > 1 else float("nan")


def convergence() -> list[dict]:
    d_exact, t_exact = V0**2 / (2 * MU * G), V0 / (MU * G)
    cases = {"2D box, x": box_2d(), "3D box, x": box_3d([V0, 0.0, 0.0]),
             "3D box, diagonal": box_3d([V0 / np.sqrt(2), V0 / np.sqrt(2), 0.0])}
    rows = []
    for case, model in cases.items():
        for name, scheme in SCHEMES.items():
            d_err, t_err, failed = [], [], 0
            for h in STEPS:
                d, t, f = stop(model, scheme, h)
                d_err.append(d - d_exact)
                t_err.append(t - t_exact)
                failed += f
            rows.append({"case": case, "scheme": name, "failed_steps": failed,
                         **{f"d_err@{h:g}": e for h, e in zip(STEPS, d_err)}, "d_order": order(STEPS, d_err),
                         "max_t_err/h": max(e / h for h, e in zip(STEPS, t_err)),
                         "min_t_err/h": min(e / h for h, e in zip(STEPS, t_err)), "t_order": order(STEPS, t_err)})
            print(rows[-1], flush=True)
    a = 0.3  # tan a = 0.309 > mu = 0.25
    mu = 0.25
    model = box_2d(v0=0.0, mu=mu, angle=a)
    for name in ("DS", "MJ"):
        errs = []
        for h in STEPS:
            q0, v0 = model.initial_state()
            sol = nsga_jax.simulate(model, SCHEMES[name], 0.0, 0.5, h, q0, v0)
            v, t = np.asarray(sol.v)[-1, :2], float(np.asarray(sol.ts)[-1])
            errs.append(float(v @ np.array([np.cos(a), np.sin(a)])) + G * (np.sin(a) - mu * np.cos(a)) * t)
        rows.append({"case": "incline a=0.3, mu=0.25: v(t_end ~ 0.5 s)", "scheme": name, "failed_steps": 0,
                     **{f"d_err@{h:g}": e for h, e in zip(STEPS, errs)}, "d_order": order(STEPS, errs)})
        print(rows[-1], flush=True)
    return rows


def final_x(p, h, scheme, adjoint, n):
    """The box's final x [m] after n steps of h, p = (mu, v0)."""
    model = box_2d(v0=p[1], mu=p[0])
    q0, v0 = model.initial_state()
    return nsga_jax.integrate(model, scheme, 0.0, n * h, h, q0, v0, n_steps=n, adjoint=adjoint).q[-1, 0]


def gradients(n=1600, grad_steps=(2e-3, 1e-3, 5e-4)) -> list[dict]:
    p = jnp.array([MU, V0])
    exact = np.array([-V0**2 / (2 * MU**2 * G), V0 / (MU * G)])
    rows = []
    tol = dict(tol_r=1e-12, tol_f=1e-12)
    for name, scheme, adjoint in (("DS", nsga_jax.DS(**tol), nsga_jax.DiscreteAdjoint()),
                                  ("DS", nsga_jax.DS(**tol), nsga_jax.ImpactTimeAdjoint()),
                                  ("MJ", nsga_jax.MJ(**tol), nsga_jax.DiscreteAdjoint())):
        value = jax.jit(lambda p, h: final_x(p, h, scheme, adjoint, n))
        grad = jax.jit(jax.grad(lambda p, h: final_x(p, h, scheme, adjoint, n)))
        for h in grad_steps:
            g = np.asarray(grad(p, h))
            fd = np.array([(float(value(p.at[k].mul(1 + 1e-6), h)) - float(value(p.at[k].mul(1 - 1e-6), h)))
                           / (2e-6 * float(p[k])) for k in range(2)])
            rows.append({"scheme": name, "adjoint": type(adjoint).__name__, "h": h,
                         "d": float(value(p, h)), "dd/dmu": g[0], "fd dd/dmu": fd[0], "exact dd/dmu": exact[0],
                         "dd/dv0": g[1], "fd dd/dv0": fd[1], "exact dd/dv0": exact[1],
                         "rel(grad-fd)": float(np.max(np.abs(g - fd) / np.abs(fd))),
                         "rel(grad-exact)": float(np.max(np.abs(g - exact) / np.abs(exact)))})
            print(rows[-1], flush=True)
    return rows


def switch(h=1e-3, n=1600, k=680, delta=1e-7) -> list[dict]:
    """The stick–slip switch, where the run's number of sliding steps N grows
    by one: for MJ where T = v0/(mu g) crosses the step time k h
    (v0* = k h mu g), for DS where it crosses the half-step time (k + 1/2) h
    (its position correction takes the last step's slip by the midpoint rule,
    so the run stops in the step whose midpoint T passes). The table gives d
    and its gradient in v0 at v0* ± delta, and the finite difference across
    the switch."""
    rows = []
    tol = dict(tol_r=1e-12, tol_f=1e-12)
    for name, scheme, steps in (("DS", nsga_jax.DS(**tol), k + 0.5), ("MJ", nsga_jax.MJ(**tol), k)):
        v_star = steps * h * MU * G
        value = jax.jit(lambda p: final_x(p, h, scheme, nsga_jax.DiscreteAdjoint(), n))
        grad = jax.jit(jax.grad(lambda p: final_x(p, h, scheme, nsga_jax.DiscreteAdjoint(), n)))
        below, above = jnp.array([MU, v_star - delta]), jnp.array([MU, v_star + delta])
        d_below, d_above = float(value(below)), float(value(above))
        rows.append({"scheme": name, "h": h, "v0*": v_star, "d(v0*-delta)": d_below, "d(v0*+delta)": d_above,
                     "dd/dv0 below": float(grad(below)[1]), "dd/dv0 above": float(grad(above)[1]),
                     "fd across": (d_above - d_below) / (2 * delta), "exact T": v_star / (MU * G)})
        print(rows[-1], flush=True)
    return rows


def markdown(rows: list[dict]) -> str:
    columns: list[str] = []
    for r in rows:
        columns += [c for c in r if c not in columns]

    def cell(x):
        return "" if x is None else (f"{x:.4g}" if isinstance(x, float) else str(x))

    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(cell(r.get(c)) for c in columns) + " |" for r in rows]
    return "\n".join(lines) + "\n"


PARTS = {"convergence": (convergence, "Sliding box and incline: errors against h"),
         "gradients": (gradients, "Gradient of the sliding distance"),
         "switch": (switch, "Gradient of the sliding distance at the stick-slip switch")}


def main(parts: list[str]) -> None:
    """Run the named parts (all by default) and write their tables."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    for name in parts or list(PARTS):
        make, title = PARTS[name]
        rows = make()
        write_csv(RESULTS / f"{name}.csv", rows)
        (RESULTS / f"{name}.md").write_text(f"# {title}\n\n{__doc__}\n{markdown(rows)}")
        print(markdown(rows))


if __name__ == "__main__":
    main(sys.argv[1:])
