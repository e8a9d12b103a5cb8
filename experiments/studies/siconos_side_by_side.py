"""nsga_jax and Siconos side by side: the same bouncing ball and the same
200-element bar, the same step sizes, one run; error (eq. 52) against the exact
solution and time per step for both.

    python experiments/studies/siconos_side_by_side.py [--out docs/results/siconos]

Siconos (Moreau–Jean, θ = 0.5, an LCP per step) runs under the Debian system
Python, which has the ``python3-siconos`` package; nothing is installed here.
Without it the script says so, gives the one command that installs it, and
stops (exit status 0). Both codes get the same matrices: the bar's consistent
mass and stiffness are assembled by nsga_jax and handed to Siconos as a
``LagrangianLinearTIDS`` with the tip constraint ``gap0 - u_tip >= 0``.

Exact solutions: the ball's is closed-form (:func:`nsga_jax.exact.bouncing_ball`);
the bar's is the continuum one, the d'Alembert solution of a uniform bar hitting
a rigid wall at speed v0 (a compression wave from the tip, reflected at the free
end, unloads the bar, which leaves at -v0 after 2L/c of contact; c = sqrt(E/ρ)),
so its error includes the 200-element mesh's dispersion, as in the paper's §4.2.
Writes ``siconos.csv`` and ``siconos.md``.
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

from nsga_jax.exact import bouncing_ball  # noqa: E402
from nsga_jax.metrics import relative_l1_error  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402
from nsga_jax.tables import write_csv  # noqa: E402

SYSTEM_PYTHON = "/usr/bin/python3"
INSTALL = "sudo apt install python3-siconos"
RUNNER = Path(__file__).with_name("_siconos_runner.py")

CASES = {
    "bouncing_ball": {"overrides": {"t_end": 3.0}, "hs": [1e-2, 3e-3, 1e-3, 3e-4]},
    "impacting_bar": {"overrides": {}, "hs": [2e-3, 1e-3, 5e-4, 2.5e-4]},
}


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


def run_siconos(scene, spec: dict, h: float, workdir: Path) -> dict:
    spec_path, result_path = workdir / "spec.npz", workdir / "result.npz"
    np.savez(spec_path, q0=scene.q0, v0=scene.v0, h=h, t_end=scene.solver["t_end"], **spec)
    proc = subprocess.run([SYSTEM_PYTHON, str(RUNNER), str(spec_path), str(result_path)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"Siconos run failed:\n{proc.stderr[-3000:]}")
    return dict(np.load(result_path))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("docs/results/siconos"))
    parser.add_argument("--repeats", type=int, default=2, help="runs per configuration; the fastest counts")
    args = parser.parse_args()
    if not siconos_available():
        print(f"Siconos is not installed for {SYSTEM_PYTHON}; this comparison is skipped.\n"
              f"Install it with:  {INSTALL}")
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, case in CASES.items():
            for h in case["hs"]:
                scene = load_scene(name, {**case["overrides"], "h": h})
                spec, exact, observed = problem(name, scene)
                results = {}
                for code, scheme in (("nsga_jax DS", "ds"), ("nsga_jax MJ", "mj")):
                    s = load_scene(name, {**case["overrides"], "h": h, "scheme": scheme, "theta": 0.5})
                    sols = [s.run() for _ in range(args.repeats)]
                    sol = sols[0]
                    ex = exact(sol.ts)
                    results[code] = ({k: relative_l1_error(sol.observables[k], ex[k]) for k in observed},
                                     1e6 * min(x.wall_time for x in sols) / sol.n_steps, sol.n_steps)
                sics = [run_siconos(scene, spec, h, Path(tmp)) for _ in range(args.repeats)]
                sic = sics[0]
                ex = exact(sic["t"])
                errors = {k: relative_l1_error(sic[field][:, col], ex[k]) for k, (field, col) in observed.items()}
                n = len(sic["t"]) - 1
                results["Siconos MJ"] = (errors, 1e6 * min(float(x["wall"]) for x in sics) / n, n)
                for code, (errs, us, steps) in results.items():
                    rows.append({"problem": name, "h": h, "code": code, "steps": steps, "us_per_step": us,
                                 **{f"error_{k}": v for k, v in errs.items()}})
                    print(f"{name} h={h:g} {code:12s} {us:8.1f} us/step  "
                          + "  ".join(f"{k} {v:.2e}" for k, v in errs.items()), flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    write_csv(args.out / "siconos.csv", rows)
    lines = []
    for name in CASES:
        mine = [r for r in rows if r["problem"] == name]
        errs = [c for c in mine[0] if c.startswith("error_")]
        lines += [f"**{name}**", "", "| h [s] | code | µs/step | " + " | ".join(e[6:] for e in errs) + " |",
                  "|---|---|---|" + "---|" * len(errs)]
        for r in mine:
            lines.append(f"| {r['h']:g} | {r['code']} | {r['us_per_step']:.1f} | "
                         + " | ".join(f"{r[e]:.2e}" for e in errs) + " |")
        lines.append("")
    (args.out / "siconos.md").write_text("\n".join(lines))
    print("\n".join(lines))
    print(f"wrote {args.out / 'siconos.csv'} and {args.out / 'siconos.md'}", file=sys.stderr)


if __name__ == "__main__":
    main()
