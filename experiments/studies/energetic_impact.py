"""Kane's paradox: the energetic impact law against Newton's restitution.

    python experiments/studies/energetic_impact.py [--box]

For each case, one run with DS(impact_law="newton") and one with
DS(impact_law="energetic") (one row with DSn), at h = 1e-4 s: the energy
change of the first impact step, relative to the energy before it, and the
velocities after it. The cases:

- a planar block (0.2 x 0.1 m, 1 kg) falling at 1 m/s onto a corner while
  spinning at +20 or -20 rad/s (two incidences), mu = 0.5, e = 1 and 0.5,
  without gravity (so the energy is the kinetic energy and its change is the
  impact law's alone) and, for e = 1, with gravity;
- a frictionless ball (2D, radius 0.1 m, e = 0.8) falling at 2 m/s and
  sliding at 1 m/s: Newton's law creates no energy and the energetic law is
  Newton's (bit for bit: a frictionless model traces Newton's jump);
- the same ball with mu = 0.5 and no slip to oppose (a frictional model whose
  impact takes no tangential impulse): equal to the tolerance;
- a sliding impact without spin reversal: the ball sliding at 2 m/s with
  mu = 0.1 (it slides through the whole impact), e = 0.8 and 1.

``--box`` adds the paper's spinning box (``rigid_box``, 3D, natural
coordinates, mu = 0.5, e = 0.8), the first impact of which Newton's law
raises from 2212.6 to 2480.6 J of kinetic energy.

Writes docs/results/friction/energetic_impact.{csv,md}.
"""

from __future__ import annotations

import os
import sys
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402
import numpy as np  # noqa: E402

from nsga_jax._process_settings import configure_jax  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

import nsga_jax  # noqa: E402
from nsga_jax.system import Gravity, PlaneContact, RigidBody2D, System  # noqa: E402

OUT = Path(__file__).resolve().parents[2] / "docs" / "results" / "friction"
H = 1e-4


def block(mu, e, omega, gravity=False):
    """The spinning block, a corner 2 mm above the floor, falling at 1 m/s."""
    a, b = 0.2, 0.1
    s = System(dim=2)
    s.add_body("block", RigidBody2D(1.0, (a * a + b * b) / 12, position=[0.0, 0.5 * np.hypot(a, b) + 0.002],
                                    angle=0.5, velocity=[0.0, -1.0], angular_velocity=omega))
    s.add_contact("floor", PlaneContact("block", normal=[0.0, 1.0], origin=[0.0, 0.0], e=e, mu=mu,
                                        points=[[-a / 2, -b / 2], [a / 2, -b / 2], [a / 2, b / 2], [-a / 2, b / 2]]))
    if gravity:
        s.add_force("g", Gravity([0.0, -9.81]))
    return s.model()


def ball(mu, e, vx, omega=0.0):
    """A solid ball (2D, r = 0.1 m, 1 kg) 2 mm above the floor, falling at 2 m/s."""
    r = 0.1
    s = System(dim=2)
    s.add_body("ball", RigidBody2D(1.0, 0.4 * r**2, position=[0.0, r + 0.002], velocity=[vx, -2.0],
                                   angular_velocity=omega))
    s.add_contact("floor", PlaneContact("ball", normal=[0.0, 1.0], origin=[0.0, 0.0], e=e, radius=r, mu=mu))
    return s.model()


def first_impact(model, scheme, t_end=0.06):
    q0, v0 = model.initial_state()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", nsga_jax.InvariantWarning)
        sol = nsga_jax.simulate(model, scheme, 0.0, t_end, H, q0, v0)
    energy = np.asarray(jax.vmap(model.energy)(sol.q, sol.v))
    k = int(np.nonzero(np.asarray(sol.impulse).sum(axis=1) > 0)[0][0])
    return (energy[k] - energy[k - 1]) / abs(energy[k - 1]), np.asarray(sol.v[k]), sol


def cases():
    for omega in (20.0, -20.0):
        for e in (1.0, 0.5):
            yield f"block, omega = {omega:+g} rad/s, mu = 0.5, no gravity", e, block(0.5, e, omega), "DS"
        yield f"block, omega = {omega:+g} rad/s, mu = 0.5, gravity", 1.0, block(0.5, 1.0, omega, True), "DS"
    yield "block, omega = +20 rad/s, mu = 0.5, no gravity", 1.0, block(0.5, 1.0, 20.0), "DSn"
    yield "ball, frictionless, vx = 1 m/s", 0.8, ball(None, 0.8, 1.0), "DS"
    yield "ball, mu = 0.5, no slip", 0.8, ball(0.5, 0.8, 0.0), "DS"
    for e in (0.8, 1.0):
        yield "ball sliding at 2 m/s, mu = 0.1", e, ball(0.1, e, 2.0), "DS"


def main(box: bool) -> None:
    rows = []
    for name, e, model, scheme in cases():
        cls = getattr(nsga_jax, scheme)
        dn, vn, _ = first_impact(model, cls(impact_law="newton"))
        de, ve, _ = first_impact(model, cls(impact_law="energetic"))
        rows.append((name, scheme, e, dn, de, vn, ve, float(np.max(np.abs(ve - vn)))))
        print(rows[-1], flush=True)
    if box:
        from nsga_jax.scenes import load_scene

        change = {}
        for law in ("newton", "energetic"):
            scene = load_scene("rigid_box", {"mu": 0.5, "t_end": 0.417, "impact_law": law})
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", nsga_jax.InvariantWarning)
                sol = scene.run()
            m = scene.model
            k = int(np.nonzero(np.asarray(sol.impulse)[:, m.n_bilateral:].sum(axis=1) > 0)[0][0])
            kinetic = [0.5 * float(sol.v[i] @ m.mass_product(sol.q[i], sol.v[i])) for i in (k - 1, k)]
            print(f"rigid_box {law}: kinetic energy {kinetic[0]:.1f} -> {kinetic[1]:.1f} J", flush=True)
            change[law] = kinetic[1] / kinetic[0] - 1.0
        rows.append(("rigid_box (3D, natural coordinates), mu = 0.5, kinetic energy", "DS", 0.8, change["newton"],
                     change["energetic"], None, None, float("nan")))
    write(rows)


def write(rows) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    with open(OUT / "energetic_impact.csv", "w") as f:
        f.write("case,scheme,e,dE_newton,dE_energetic,v_newton,v_energetic,max_dv\n")
        for name, scheme, e, dn, de, vn, ve, dv in rows:
            fmt = (lambda v: "" if v is None else " ".join(f"{x:.6g}" for x in v))  # noqa: E731
            f.write(f'"{name}",{scheme},{e},{dn:.6e},{de:.6e},{fmt(vn)},{fmt(ve)},{dv:.3e}\n')
    lines = ["| case | scheme | e | ΔE/E Newton | ΔE/E energetic | (vx, vy, ω)⁺ Newton | (vx, vy, ω)⁺ energetic |"
             " max \\|Δv\\| |", "|---|---|---|---|---|---|---|---|"]
    for name, scheme, e, dn, de, vn, ve, dv in rows:
        vec = (lambda v: "–" if v is None else "(" + ", ".join(f"{x:.4g}" for x in v) + ")")  # noqa: E731
        gap = "–" if np.isnan(dv) else f"{dv:.2g}"
        lines.append(f"| {name} | {scheme} | {e:g} | {dn:+.3g} | {de:+.3g} | {vec(vn)} | {vec(ve)} | {gap} |")
    (OUT / "energetic_impact.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main("--box" in sys.argv[1:])
