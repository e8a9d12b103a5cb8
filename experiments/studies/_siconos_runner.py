"""Run one problem in Siconos (Moreau–Jean, θ = 0.5, an LCP or a 2D friction
contact problem per step) and save its trajectory.

Run by ``experiments/studies/siconos_side_by_side.py`` with the Debian system Python,
which has the ``python3-siconos`` package (it needs only NumPy besides):

    /usr/bin/python3 experiments/studies/_siconos_runner.py SPEC.npz RESULT.npz

SPEC holds a linear time-invariant Lagrangian system and one unilateral
constraint y = H q + b >= 0 with Newton's impact law: q0, v0, M, K (n × n),
f_ext (n,), H (1 × n), b (1,), e, h, t_end, and ``observe`` (indices of the
coordinates to record). With ``mu`` in SPEC the contact has Coulomb friction:
H is 2 × n, its first row the normal (the gap), its second the tangent, the
law ``NewtonImpactFrictionNSL(e, 0, mu, 2)`` and the one-step problem a 2D
``FrictionContact`` (Siconos' 2D NSGS, its tolerance tightened from 1e-4 to
1e-12; an LCP's default solver, Lemke, is direct). RESULT holds t, q and v
at those indices, and the wall time of the time loop [s].
"""

import sys
import time

import numpy as np
import siconos.kernel as sk
import siconos.numerics as sn


def main(spec_path: str, result_path: str) -> None:
    spec = np.load(spec_path)
    n = len(spec["q0"])
    body = sk.LagrangianLinearTIDS(spec["q0"], spec["v0"], spec["M"], spec["K"], np.zeros((n, n)))
    body.setFExtPtr(spec["f_ext"])
    relation = sk.LagrangianLinearTIR(spec["H"], spec["b"])
    if "mu" in spec:  # Coulomb friction: normal and tangent rows
        law = sk.NewtonImpactFrictionNSL(float(spec["e"]), 0.0, float(spec["mu"]), 2)
        one_step = sk.FrictionContact(2)
        one_step.numericsSolverOptions().dparam[sn.SICONOS_DPARAM_TOL] = 1e-12
    else:
        law = sk.NewtonImpactNSL(float(spec["e"]))
        one_step = sk.LCP()
    interaction = sk.Interaction(law, relation)
    t_end, h = float(spec["t_end"]), float(spec["h"])
    system = sk.NonSmoothDynamicalSystem(0.0, t_end)
    system.insertDynamicalSystem(body)
    system.link(interaction, body)
    simulation = sk.TimeStepping(system, sk.TimeDiscretisation(0.0, h), sk.MoreauJeanOSI(0.5), one_step)
    idx = spec["observe"]
    n_steps = int(np.floor(t_end / h + 1e-9))
    ts = np.zeros(n_steps + 1)
    qs = np.zeros((n_steps + 1, len(idx)))
    vs = np.zeros((n_steps + 1, len(idx)))
    qs[0], vs[0] = spec["q0"][idx], spec["v0"][idx]
    q, v = body.q(), body.velocity()
    start = time.perf_counter()
    for k in range(1, n_steps + 1):
        simulation.computeOneStep()
        ts[k] = simulation.nextTime()
        qs[k], vs[k] = q[idx], v[idx]
        simulation.nextStep()
    wall = time.perf_counter() - start
    np.savez(result_path, t=ts, q=qs, v=vs, wall=wall)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
