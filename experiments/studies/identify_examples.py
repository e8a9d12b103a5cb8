"""Parameter identification through impacts (optax L-BFGS, gradients through the
whole nonsmooth trajectory), from noisy synthetic data, starting 30 % off.

    python experiments/studies/identify_examples.py [--only bar,ball,box] [--out experiments/out/identify]

(a) impacting bar: Young's modulus E and restitution e from the tip displacement
    and velocity, in two stages: E from the displacement alone, then E and e
    from both (the velocity signal is dominated by the instants the contact
    opens and closes, whose motion the discrete gradient does not see, and e
    barely shows in the displacement: fitted together from 30 % off, the
    optimiser stalls); (b) bouncing ball: e and the initial height from heights;
(c) rigid box: e from the gap history of the vertex that hits the floor.
Each case writes identification.json, loss.png, fit.png and data.csv under
--out/<case>; the table goes to docs/results/identification/summary.md and the
figures to docs/figures/identify_<case>_*.png.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

import nsga_jax as nj  # noqa: E402
from nsga_jax._identify import Data, identify, synthetic_data, write_identification  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them
ADJOINT = nj.ImpactTimeAdjoint()  # the adjoint of the committed table (recorded in commit 4670a9a)

FIGURES = Path("docs/figures")
RESULTS = Path("docs/results/identification")

# name: (scene, solver/scene overrides, observables, sample every, true values, initial values,
#        stages: (parameters, observables) fitted in turn, each from where the last stopped)
CASES = {
    "bar": ("impacting_bar", {"t_end": 1.5, "h": 1e-3}, ["tip_u", "tip_v"], 5,
            {"E": 900.0, "e": 0.5}, {"E": 1170.0, "e": 0.35},
            [(["E"], ["tip_u"]), (["E", "e"], ["tip_u", "tip_v"])]),
    "ball": ("bouncing_ball", {"t_end": 1.5, "h": 1e-3}, ["z"], 5,
             {"e": 0.8, "height": 1.0}, {"e": 0.56, "height": 1.3}, [(["e", "height"], ["z"])]),
    "box": ("rigid_box", {"t_end": 0.69, "h": 1e-3}, ["gap_5"], 3,
            {"e": 0.8}, {"e": 0.56}, [(["e"], ["gap_5"])]),
}
NOISE = 0.01  # standard deviation, as a fraction of each observable's RMS


def run_case(name: str, out: Path) -> dict:
    scene, overrides, observables, every, true, initial, stages = CASES[name]
    t = time.perf_counter()
    data = synthetic_data(scene, {**overrides, **true}, observables, noise=NOISE, seed=1, every=every)
    current, stage_summaries = dict(initial), []
    for names, stage_observables in stages:
        stage_data = Data(t=data.t, values={k: data.values[k] for k in stage_observables})
        print(f"{name}: fitting {', '.join(names)} to {', '.join(stage_observables)}", flush=True)
        result = identify(scene, names, stage_data, overrides={**overrides, **current}, true=true, adjoint=ADJOINT,
                          progress=True)
        current.update(result.recovered)
        stage_summaries.append({"parameters": names, "observables": stage_observables, **{
            k: result.summary()[k] for k in ("recovered", "iterations", "evaluations", "stopped_by",
                                             "final_loss", "wall_time_s", "compile_time_s")}})
    case_out = out / name
    found = ", ".join(f"{k}: {initial[k]:.4g} → {current[k]:.4g} (true {true[k]:.4g})" for k in true)
    last = f"; last of {len(stages)} stages shown" if len(stages) > 1 else ""
    paths = write_identification(result, stage_data, case_out, title=f"{found}; {NOISE:.0%} noise{last}",
                                 scene=load_scene(scene, {**overrides, **current}))
    data.save(case_out / "data.csv")
    FIGURES.mkdir(parents=True, exist_ok=True)
    for key in ("loss", "fit"):
        shutil.copy(paths[key], FIGURES / f"identify_{name}_{key}.png")
    summary = result.summary()
    summary.update(
        scene=scene, observables=observables, samples=int(data.t.size), noise=NOISE, overrides=overrides,
        initial=initial, recovered={k: current[k] for k in true},
        relative_error={k: abs(current[k] / true[k] - 1.0) for k in true}, stages=stage_summaries,
        iterations=sum(s["iterations"] for s in stage_summaries),
        wall_time_s=sum(s["wall_time_s"] for s in stage_summaries),
        compile_time_s=sum(s["compile_time_s"] for s in stage_summaries), elapsed_s=time.perf_counter() - t)
    print(json.dumps(summary, indent=1), flush=True)
    return summary


def bar_checks() -> dict:
    """What docs/gradients.md says about the bar: e barely shows in the tip signals,
    and fitting E and e together from 30 % off stalls."""
    import jax.numpy as jnp

    from nsga_jax import integrate
    from nsga_jax.scenes import load_scene, make_scheme, parametrize

    scene, overrides, observables, every, true, initial, _ = CASES["bar"]
    params, build = parametrize(scene, overrides, ["E", "e"])
    scheme = make_scheme(load_scene(scene, overrides).solver)

    @jax.jit
    def signals(p):
        model, q0, v0, observables = build(p)
        n = round(overrides["t_end"] / overrides["h"])
        obs = observables(integrate(model, scheme, 0.0, n * overrides["h"], overrides["h"], q0, v0, n_steps=n))
        return obs["tip_u"], obs["tip_v"]

    u_true, v_true = signals(true)
    u_e, v_e = signals({"E": true["E"], "e": initial["e"]})

    def rel(a, b):
        return float(jnp.sqrt(jnp.mean((a - b) ** 2) / jnp.mean(b**2)))

    data = synthetic_data(scene, {**overrides, **true}, observables, noise=NOISE, seed=1, every=every)
    joint = identify(scene, ["E", "e"], data, overrides={**overrides, **initial}, true=true, adjoint=ADJOINT)
    out = {"e_change": {"from": true["e"], "to": initial["e"], "tip_u_rms_change": rel(u_e, u_true),
                        "tip_v_rms_change": rel(v_e, v_true)},
           "joint_fit_from_initial": {k: joint.summary()[k] for k in ("recovered", "relative_error", "iterations",
                                                                      "stopped_by", "initial_loss", "final_loss")}}
    print(json.dumps(out, indent=1), flush=True)
    return out


def table(summaries: dict) -> str:
    lines = ["| case | data | parameter | true | initial | recovered | error | iterations | "
             "optimise [s] | compile [s] |", "|" + "---|" * 10]
    for name, s in summaries.items():
        for i, k in enumerate(s["true"]):
            stages = f", {len(s['stages'])} stages" if len(s["stages"]) > 1 else ""
            head = (f"{name} ({s['scene']}) | {', '.join(s['observables'])}, {s['samples']} samples{stages}"
                    if i == 0 else " | ")
            tail = (f"{s['iterations']} | {s['wall_time_s']:.1f} | {s['compile_time_s']:.1f}"
                    if i == 0 else " | | ")
            lines.append(f"| {head} | {k} | {s['true'][k]:g} | {s['initial'][k]:g} | "
                         f"{s['recovered'][k]:.5g} | {100 * s['relative_error'][k]:.2f} % | {tail} |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(CASES))
    ap.add_argument("--out", type=Path, default=Path("experiments/out/identify"))
    ap.add_argument("--bar-checks", action="store_true",
                    help="only the bar's restitution sensitivity and joint fit "
                         "(docs/results/identification/bar_checks.json)")
    args = ap.parse_args()
    if args.bar_checks:
        RESULTS.mkdir(parents=True, exist_ok=True)
        (RESULTS / "bar_checks.json").write_text(json.dumps(bar_checks(), indent=2) + "\n")
        return
    summaries = {name: run_case(name, args.out) for name in args.only.split(",")}
    RESULTS.mkdir(parents=True, exist_ok=True)
    previous = RESULTS / "summary.json"
    merged = json.loads(previous.read_text()) if previous.exists() else {}
    merged.update(summaries)
    merged = {k: merged[k] for k in CASES if k in merged}
    previous.write_text(json.dumps(merged, indent=2) + "\n")
    (RESULTS / "summary.md").write_text(table(merged) + "\n")
    print(table(merged))


if __name__ == "__main__":
    main()
