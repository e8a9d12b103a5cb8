"""nsga_jax and Siconos side by side: the same bouncing ball, the same
200-element bar and the same point mass sliding on a floor with Coulomb
friction, the same step sizes, one run; error (eq. 52) against the exact
solution and time per step for both.

    python experiments/studies/siconos_side_by_side.py [--out docs/results/siconos] [--cases sliding_mass]

Siconos (Moreau–Jean, θ = 0.5, an LCP per step; with friction a 2D
``FrictionContact`` problem per step) runs under the Debian system
Python, which has the ``python3-siconos`` package; nothing is installed here.
Without it the script says so, gives the one command that installs it, and
stops (exit status 0). Both codes get the same matrices: the bar's consistent
mass and stiffness are assembled by nsga_jax and handed to Siconos as a
``LagrangianLinearTIDS`` with the tip constraint ``gap0 - u_tip >= 0``.

Exact solutions: the ball's is closed-form (:func:`nsga_jax._exact.bouncing_ball`);
the bar's is the continuum one, the d'Alembert solution of a uniform bar hitting
a rigid wall at speed v0 (a compression wave from the tip, reflected at the free
end, unloads the bar, which leaves at -v0 after 2L/c of contact; c = sqrt(E/ρ)),
so its error includes the 200-element mesh's dispersion, as in the paper's §4.2.

The sliding mass: a point mass m (x, y) on the floor y >= 0 under gravity g,
started on it at horizontal speed v0, with Coulomb's coefficient μ (e = 0):
Siconos gets the relation y = H q with H = [[0, 1], [1, 0]] (normal row
first, tangent row second) and ``NewtonImpactFrictionNSL(0, 0, μ, 2)``,
nsga_jax a ``PointMass`` with a ``PlaneContact(mu=μ)``. Exact: it decelerates
at μ g, x(t) = v0 t - μ g t²/2, until t* = v0/(μ g), then rests at
v0²/(2 μ g); the error is taken on x and vx over [0, T], T past the stop.

Each table has below it the largest difference between nsga_jax's MJ and
Siconos' Moreau–Jean on the same time grid (relative to the exact
solution's largest value): the same scheme, so it should be round-off.
Writes ``siconos.csv``, ``siconos_mj_agreement.csv`` and ``siconos.md``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from nsga_jax._exact import bouncing_ball  # noqa: E402
from nsga_jax._metrics import relative_l1_error  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax._tables import write_csv  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

SYSTEM_PYTHON = "/usr/bin/python3"
INSTALL = "sudo apt install python3-siconos"
RUNNER = Path(__file__).with_name("_siconos_runner.py")

CASES = {
    "bouncing_ball": {"overrides": {"t_end": 3.0}, "hs": [1e-2, 3e-3, 1e-3, 3e-4]},
    "impacting_bar": {"overrides": {}, "hs": [2e-3, 1e-3, 5e-4, 2.5e-4]},
    "sliding_mass": {"overrides": {}, "hs": [1e-2, 3e-3, 1e-3, 3e-4]},
}
# The sliding mass [kg, m/s², -, m/s, s]: it stops at t* = v0/(μ g) = 0.68 s, T = 1.2 s
# (a whole number of every step size).
SLIDING = {"mass": 1.0, "gravity": 9.81, "mu": 0.3, "velocity": 2.0, "t_end": 1.2}


def siconos_available() -> bool:
    if not Path(SYSTEM_PYTHON).exists():
        return False
    probe = subprocess.run([SYSTEM_PYTHON, "-c", "import siconos.kernel"], capture_output=True)
    return probe.returncode == 0


def bar_exact(t, distance_from_tip: float, v0: float, gap: float, c: float, length: float):
    """Displacement and velocity of the material point ``distance_from_tip`` [m]
    from the tip of a uniform bar (wave speed c) moving at v0 toward a rigid wall
    at distance ``gap`` (continuum solution, until the bar has left the wall)."""
    t = np.asarray(t, float)
    t_hit = gap / v0
    t_stop = t_hit + distance_from_tip / c  # the compression wave arrives: at rest
    t_back = t_hit + (2 * length - distance_from_tip) / c  # the unloading wave arrives: -v0
    u = np.where(t <= t_stop, v0 * t, np.where(t <= t_back, v0 * t_stop, v0 * t_stop - v0 * (t - t_back)))
    v = np.where(t <= t_stop, v0, np.where(t <= t_back, 0.0, -v0))
    return u, v


def problem(name: str, scene):
    """Siconos spec (matrices, constraint, observed coordinates) and the exact
    solution of the observed quantities, ``ts -> {name: values}``."""
    p = scene.parameters
    n = scene.model.n_dof
    zeros = np.zeros(n)
    M = np.asarray(scene.model.mass(zeros))
    if name == "bouncing_ball":
        spec = dict(M=M, K=np.zeros((1, 1)), f_ext=np.array([-p["mass"] * p["gravity"]]), H=np.array([[1.0]]),
                    b=np.array([0.0]), e=p["e"], observe=np.array([0]))

        def exact(ts):
            z, vz = bouncing_ball(ts, p["height"], p["velocity"], p["gravity"], p["e"])
            return {"z": z, "vz": vz}

        return spec, exact, {"z": ("q", 0), "vz": ("v", 0)}
    K = np.asarray(scene.model.tangents(zeros, zeros, 0.0)[0])
    H = np.zeros((1, n))
    H[0, -1] = -1.0
    node = n - 1 - int(round(0.45 * p["n_elements"] / p["length"]))
    s = (n - 1 - node) * p["length"] / p["n_elements"]
    spec = dict(M=M, K=K, f_ext=np.zeros(n), H=H, b=np.array([p["gap"]]), e=p["e"], observe=np.array([node, n - 1]))
    c = np.sqrt(p["E"] / p["rho"])

    def exact(ts):
        u, v = bar_exact(ts, s, p["velocity"], p["gap"], c, p["length"])
        u_tip, v_tip = bar_exact(ts, 0.0, p["velocity"], p["gap"], c, p["length"])
        return {"node045_u": u, "node045_v": v, "tip_u": u_tip, "tip_v": v_tip}

    return spec, exact, {"node045_u": ("q", 0), "node045_v": ("v", 0), "tip_u": ("q", 1), "tip_v": ("v", 1)}


def sliding_exact(t, v0: float, mu: float, g: float):
    """Position x [m] and velocity vx [m/s] of a mass sliding from x = 0 at v0
    against Coulomb friction μ under gravity g: deceleration μ g until it
    stops at t* = v0/(μ g), then at rest at v0²/(2 μ g)."""
    t_stop = v0 / (mu * g)
    tc = np.minimum(np.asarray(t, float), t_stop)
    return v0 * tc - 0.5 * mu * g * tc**2, v0 - mu * g * tc


def sliding_model():
    """The sliding mass in nsga_jax: a 2D point mass on the plane y = 0 with μ, under gravity."""
    from nsga_jax.system import Gravity, PlaneContact, PointMass, System

    p = SLIDING
    s = System(dim=2)
    s.add_body("mass", PointMass(p["mass"], position=[0.0, 0.0], velocity=[p["velocity"], 0.0]))
    s.add_contact("floor", PlaneContact("mass", normal=[0.0, 1.0], origin=[0.0, 0.0], e=0.0, mu=p["mu"]))
    s.add_force("gravity", Gravity([0.0, -p["gravity"]]))
    return s.model()


def sliding_problem():
    """Siconos spec, exact solution and observed coordinates of the sliding mass."""
    p = SLIDING
    m, g = p["mass"], p["gravity"]
    spec = dict(M=m * np.eye(2), K=np.zeros((2, 2)), f_ext=np.array([0.0, -m * g]),
                H=np.array([[0.0, 1.0], [1.0, 0.0]]), b=np.zeros(2), e=0.0, mu=p["mu"], observe=np.array([0, 1]))

    def exact(ts):
        x, vx = sliding_exact(ts, p["velocity"], p["mu"], g)
        return {"x": x, "vx": vx}

    return spec, exact, {"x": ("q", 0), "vx": ("v", 0)}


def energy_growth(q_y, v) -> float:
    """Largest growth between steps of the sliding mass' energy per unit mass,
    |v|²/2 + g y [J/kg] (friction and the floor only take energy away)."""
    energy = 0.5 * np.sum(np.asarray(v) ** 2, axis=1) + SLIDING["gravity"] * np.asarray(q_y)
    return float(np.max(np.diff(energy), initial=0.0))


def check_energy(label: str, growth: float) -> None:
    bound = 1e-9 * SLIDING["velocity"] ** 2
    if growth > bound:
        raise RuntimeError(f"{label}: the sliding mass' energy grew by {growth:.3e} J/kg in a step")


def run_nsga(name: str, case: dict, h: float, scheme: str, repeats: int):
    """nsga_jax's runs of one case: (ts, {observed: values}, best wall time [s], steps)."""
    if name == "sliding_mass":
        import nsga_jax

        model = sliding_model()
        q0, v0 = model.initial_state()
        integrator = nsga_jax.DS() if scheme == "ds" else nsga_jax.MJ(theta=0.5)
        sols = [nsga_jax.simulate(model, integrator, 0.0, SLIDING["t_end"], h, q0, v0) for _ in range(repeats)]
        sol = sols[0]
        q, v = np.asarray(sol.q), np.asarray(sol.v)
        if np.any(sol.failed_steps):
            raise RuntimeError(f"nsga_jax {scheme} failed steps on the sliding mass at h = {h:g}")
        check_energy(f"nsga_jax {scheme} h={h:g}", energy_growth(q[:, 1], v))
        observables = {"x": q[:, 0], "vx": v[:, 0]}
        return np.asarray(sol.ts), observables, min(x.wall_time for x in sols), sol.n_steps
    s = load_scene(name, {**case["overrides"], "h": h, "scheme": scheme, "theta": 0.5})
    sols = [s.run() for _ in range(repeats)]
    sol = sols[0]
    return np.asarray(sol.ts), sol.observables, min(x.wall_time for x in sols), sol.n_steps


def setup(name: str, case: dict, h: float):
    """Siconos spec (with q0, v0, h, t_end), exact solution and observed coordinates of one case."""
    if name == "sliding_mass":
        spec, exact, observed = sliding_problem()
        return {**spec, "q0": np.zeros(2), "v0": np.array([SLIDING["velocity"], 0.0]), "h": h,
                "t_end": SLIDING["t_end"]}, exact, observed
    scene = load_scene(name, {**case["overrides"], "h": h})
    spec, exact, observed = problem(name, scene)
    return {**spec, "q0": scene.q0, "v0": scene.v0, "h": h, "t_end": scene.solver["t_end"]}, exact, observed


def run_siconos(spec: dict, workdir: Path) -> dict:
    spec_path, result_path = workdir / "spec.npz", workdir / "result.npz"
    np.savez(spec_path, **spec)
    proc = subprocess.run([SYSTEM_PYTHON, str(RUNNER), str(spec_path), str(result_path)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"Siconos run failed:\n{proc.stderr[-3000:]}")
    return dict(np.load(result_path))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("docs/results/siconos"))
    parser.add_argument("--repeats", type=int, default=2, help="runs per configuration; the fastest counts")
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES),
                        help="run only these cases (the committed tables hold all of them, from one run)")
    args = parser.parse_args()
    if not siconos_available():
        print(f"Siconos is not installed for {SYSTEM_PYTHON}; this comparison is skipped.\n"
              f"Install it with:  {INSTALL}")
        return
    rows, agreement = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.cases:
            case = CASES[name]
            for h in case["hs"]:
                spec, exact, observed = setup(name, case, h)
                results, trajectories = {}, {}
                for code, scheme in (("nsga_jax DS", "ds"), ("nsga_jax MJ", "mj")):
                    ts, obs, wall, steps = run_nsga(name, case, h, scheme, args.repeats)
                    ex = exact(ts)
                    results[code] = ({k: relative_l1_error(obs[k], ex[k]) for k in observed},
                                     1e6 * wall / steps, steps)
                    trajectories[code] = (ts, obs)
                sics = [run_siconos(spec, Path(tmp)) for _ in range(args.repeats)]
                sic = sics[0]
                if name == "sliding_mass":
                    check_energy(f"Siconos h={h:g}", energy_growth(sic["q"][:, 1], sic["v"]))
                ex = exact(sic["t"])
                sic_obs = {k: sic[field][:, col] for k, (field, col) in observed.items()}
                errors = {k: relative_l1_error(sic_obs[k], ex[k]) for k in observed}
                n = len(sic["t"]) - 1
                results["Siconos MJ"] = (errors, 1e6 * min(float(x["wall"]) for x in sics) / n, n)
                ts, obs = trajectories["nsga_jax MJ"]
                if len(ts) != len(sic["t"]) or not np.allclose(ts, sic["t"], rtol=0, atol=1e-9 * h):
                    raise RuntimeError(f"{name} h={h:g}: the two codes' time grids differ")
                agreement.append({"problem": name, "h": h, **{
                    k: float(np.max(np.abs(obs[k] - sic_obs[k])) / np.max(np.abs(ex[k]))) for k in observed}})
                for code, (errs, us, steps) in results.items():
                    rows.append({"problem": name, "h": h, "code": code, "steps": steps, "us_per_step": us,
                                 **{f"error_{k}": v for k, v in errs.items()}})
                    print(f"{name} h={h:g} {code:12s} {us:8.1f} us/step  "
                          + "  ".join(f"{k} {v:.2e}" for k, v in errs.items()), flush=True)
                print(f"{name} h={h:g} max |nsga_jax MJ - Siconos MJ| / max |exact|  "
                      + "  ".join(f"{k} {v:.1e}" for k, v in agreement[-1].items() if k in observed), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "siconos.csv", rows)
    write_csv(args.out / "siconos_mj_agreement.csv",
              [{"problem": a["problem"], "h": a["h"], "quantity": k, "max_relative_difference": v}
               for a in agreement for k, v in a.items() if k not in ("problem", "h")])
    lines = []
    for name in args.cases:
        mine = [r for r in rows if r["problem"] == name]
        errs = [c for c in mine[0] if c.startswith("error_")]
        lines += [f"**{name}**", "", "| h [s] | code | µs/step | " + " | ".join(e[6:] for e in errs) + " |",
                  "|---|---|---|" + "---|" * len(errs)]
        for r in mine:
            lines.append(f"| {r['h']:g} | {r['code']} | {r['us_per_step']:.1f} | "
                         + " | ".join(f"{r[e]:.2e}" for e in errs) + " |")
        lines += ["", "max |nsga_jax MJ − Siconos MJ| / max |exact|: "
                  + "; ".join(f"h = {a['h']:g}: " + ", ".join(f"{e[6:]} {a[e[6:]]:.1e}" for e in errs)
                              for a in agreement if a["problem"] == name), ""]
    (args.out / "siconos.md").write_text("\n".join(lines))
    print("\n".join(lines))
    print(f"wrote {args.out / 'siconos.csv'}, {args.out / 'siconos_mj_agreement.csv'} and {args.out / 'siconos.md'}",
          file=sys.stderr)


if __name__ == "__main__":
    main()
