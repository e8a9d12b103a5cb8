"""Gradients through impacts: the discrete-map gradient, the event-aware gradient
(``adjoint=ImpactTimeAdjoint()``), finite differences with a small and a large step, and
the exact continuous-time derivative, for several step sizes.

    python experiments/studies/event_gradients.py [--only ball,pendulum,bar,box_flat]

Cases (loss: mean square mismatch of one observable sampled every 10 ms against
data from the exact solution at other parameter values):

- ball: z over 1.5 s (3 impacts), derivatives in e and the drop height h0 at
  e = 0.85, h0 = 1 (data: e = 0.8); exact derivative from the closed-form
  solution (central difference, step 1e-6);
- pendulum: x over 2 s (2 impacts), derivatives in the wall position and e at
  wall_x = -0.28, e = 0.7 (data: wall_x = -0.3); exact derivative from the
  event-driven reference (diffrax, tolerance 1e-12; central difference, step 1e-5);
- bar: tip displacement over 1.5 s, derivatives in E and v0 at E = 950 Pa,
  v0 = 10 m/s (data: the DS solution at h = 1e-5 with E = 900 Pa); the
  200-element model has no closed form, so its continuous-time derivative is a
  central difference with a 1 % step of the loss at h = 1e-5, where the
  staircase's steps are 100 times finer than at 1e-3;
- box_flat: the box dropped flat (four simultaneous vertex contacts, six
  rigidity constraints), centre height over 0.8 s, derivatives in the drop
  height z0 and e at z0 = 0.65 m, e = 0.5 (data: drop from 0.5 m above the
  floor, e = 0.4); exact derivative from the ball's closed form.

Writes docs/results/event_gradients/gradients.{csv,md} and
docs/figures/event_gradients_{ball,convergence}.png. ``--replot`` redraws the
convergence figure from the committed CSV (seconds); ``--ball-sweep`` recomputes
and draws the ball's loss and gradient against e alone (about a minute).
"""

from __future__ import annotations

import argparse
import csv
import os
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import nsga_jax  # noqa: E402
from nsga_jax import _plotting as plotting  # noqa: E402
from nsga_jax._adjoint import adjoint_named  # noqa: E402
from nsga_jax._exact import bouncing_ball, rigid_pendulum  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import load_scene, parametrize  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

G = 9.81
HS = (1e-3, 3e-4, 1e-4)
RESULTS = Path("docs/results/event_gradients")
FIGURES = Path("docs/figures")
PENDULUM = dict(length=1.0, gravity=G, angle=1.0, omega=0.0)


def central(f, x: float, step: float) -> float:
    return (f(x + step) - f(x - step)) / (2 * step)


class Case:
    """A loss on one observable of a scene and its continuous-time reference derivative."""

    def __init__(self, name, scene, observable, t_end, params, data_t, data_y, reference_loss):
        self.name, self.scene, self.observable, self.t_end = name, scene, observable, t_end
        self.params, self.data_t, self.data_y = params, data_t, data_y
        self.reference_loss = reference_loss  # (name, value) -> loss of the continuous-time model

    def ds_loss(self, h: float, adjoint: str):
        """A jitted ``p -> loss`` of the DS trajectory at step h."""
        n = int(round(self.t_end / h))
        params, build = parametrize(self.scene, {**self.params, "h": h}, list(self.params))
        ts = jnp.arange(n + 1) * h
        t_data, y_data = jnp.asarray(self.data_t), jnp.asarray(self.data_y)

        def loss(p):
            model, q0, v0, observables = build(p)
            y = observables(nsga_jax.integrate(model, nsga_jax.DS(), 0.0, n * h, h, q0, v0, n_steps=n,
                                               adjoint=adjoint_named(adjoint)))
            return jnp.mean((jnp.interp(t_data, ts, y[self.observable]) - y_data) ** 2)

        return params, loss


def ball_case() -> Case:
    t = np.arange(0.0, 1.5 + 1e-12, 0.01)
    data = bouncing_ball(t, 1.0, 0.0, G, 0.8)[0]
    p0 = {"e": 0.85, "height": 1.0}

    def ref(name, value):
        p = {**p0, name: value}
        return float(np.mean((bouncing_ball(t, p["height"], 0.0, G, p["e"])[0] - data) ** 2))

    return Case("ball", "bouncing_ball", "z", 1.5, p0, t, data, ref)


def pendulum_case() -> Case:
    t = np.arange(0.0, 2.0 + 1e-12, 0.01)
    data = rigid_pendulum(t, wall_x=-0.3, e=0.7, **PENDULUM)[0][0]
    p0 = {"wall_x": -0.28, "e": 0.7}

    def ref(name, value):
        p = {**p0, name: value}
        return float(np.mean((rigid_pendulum(t, wall_x=p["wall_x"], e=p["e"], **PENDULUM)[0][0] - data) ** 2))

    return Case("pendulum", "rigid_pendulum", "x", 2.0, p0, t, data, ref)


def bar_case() -> Case:
    t = np.arange(0.0, 1.5 + 1e-12, 0.01)
    h_ref = 1e-5

    def tip(p):
        sol = load_scene("impacting_bar", {**p, "h": h_ref, "t_end": 1.5}).run(saveat=nsga_jax.SaveAt(every=100))
        return np.interp(t, sol.ts, sol.observables["tip_u"])

    data = tip({"E": 900.0})
    p0 = {"E": 950.0, "velocity": 10.0}

    def ref(name, value):
        return float(np.mean((tip({**p0, name: value}) - data) ** 2))

    return Case("bar", "impacting_bar", "tip_u", 1.5, p0, t, data, ref)


def box_case() -> Case:
    """The box of configs/extreme/box_flat.toml: four vertices hit at once, six
    rigidity constraints. Dropped flat it moves like a ball whose height is the
    centre's minus lz/2, so the closed form is its exact solution."""
    t = np.arange(0.0, 0.8 + 1e-12, 0.01)
    half = 0.15
    data = bouncing_ball(t, 0.5, 0.0, G, 0.4)[0] + half
    p0 = {"z0": 0.65, "e": 0.5}

    def ref(name, value):
        p = {**p0, name: value}
        return float(np.mean((bouncing_ball(t, p["z0"] - half, 0.0, G, p["e"])[0] + half - data) ** 2))

    return Case("box_flat", "configs/extreme/box_flat.toml", "z", 0.8, p0, t, data, ref)


CASES = {"ball": ball_case, "pendulum": pendulum_case, "bar": bar_case, "box_flat": box_case}
# relative step of the reference derivative's central difference
REFERENCE_STEP = {"ball": 1e-6, "pendulum": 1e-5, "bar": 1e-2, "box_flat": 1e-6}


def study(case: Case) -> list[dict]:
    rows = []
    reference = {k: central(lambda x, k=k: case.reference_loss(k, x), v, REFERENCE_STEP[case.name] * abs(v))
                 for k, v in case.params.items()}
    for h in HS:
        t0 = time.perf_counter()
        params, discrete = case.ds_loss(h, "discrete")
        _, event = case.ds_loss(h, "event")
        g_discrete = jax.jit(jax.grad(discrete))(params)
        g_event = jax.jit(jax.grad(event))(params)
        value = jax.jit(discrete)
        for k, v in case.params.items():
            def f(x, k=k):
                return float(value({**params, k: jnp.asarray(x)}))

            rows.append({
                "case": case.name, "parameter": k, "h": h, "reference": reference[k],
                "discrete": float(g_discrete[k]), "event": float(g_event[k]),
                "fd_small": central(f, v, 1e-6 * abs(v)), "fd_large": central(f, v, 1e-2 * abs(v)),
            })
        print(f"{case.name} h = {h:g}: " + "; ".join(
            f"{r['parameter']}: ref {r['reference']:.5g} discrete {r['discrete']:.5g} event {r['event']:.5g} "
            f"fd(1e-6) {r['fd_small']:.5g} fd(1e-2) {r['fd_large']:.5g}" for r in rows[-len(case.params):])
            + f" ({time.perf_counter() - t0:.0f} s)", flush=True)
    return rows


def table(rows) -> str:
    def err(x, ref):
        return f"{x:.4g} ({100 * (x / ref - 1):+.1f} %)"

    lines = ["| case | parameter | h [s] | continuous-time | discrete gradient | event-aware gradient | "
             "FD, step 1e-6 | FD, step 1e-2 |", "|" + "---|" * 8]
    for r in rows:
        ref = float(r["reference"])
        lines.append(f"| {r['case']} | {r['parameter']} | {float(r['h']):g} | {ref:.4g} | "
                     f"{err(float(r['discrete']), ref)} | {err(float(r['event']), ref)} | "
                     f"{err(float(r['fd_small']), ref)} | {err(float(r['fd_large']), ref)} |")
    return "\n".join(lines)


CASE_SCENES = {"ball": "bouncing_ball", "pendulum": "rigid_pendulum", "bar": "impacting_bar",
               "box_flat": "rigid_box (flat drop)"}
GRADIENT_STYLE = {
    "discrete": dict(marker="s", linestyle="--", markersize=7.5, markerfacecolor="none", markeredgewidth=1.3,
                     color="C0", label="discrete gradient (the staircase's)"),
    "event": dict(marker="o", linestyle="-", markersize=4.0, color="C3", label="event-aware gradient"),
}


def plot_convergence(rows, path: Path) -> None:
    keys = sorted({(r["case"], r["parameter"]) for r in rows}, key=lambda k: (list(CASES).index(k[0]), k[1]))
    hs_all = sorted({float(r["h"]) for r in rows})
    ncols = 4
    nrows = -(-len(keys) // ncols)
    with plotting.style():
        fig, axes = plotting.figure(nrows, ncols, panel=(3.0, 2.5))
        plotting.hide_unused(axes, len(keys))
        for ax, (case, param) in zip(axes.flat, keys):
            mine = [r for r in rows if r["case"] == case and r["parameter"] == param]
            hs = [float(r["h"]) for r in mine]
            for mode, look in GRADIENT_STYLE.items():
                ax.loglog(hs, [abs(float(r[mode]) / float(r["reference"]) - 1) for r in mine], **look)
            ax.set_title(f"{CASE_SCENES[case]}: dL/d{param}", loc="left")
            ax.set_xlabel("h [s]")
            ax.set_ylabel(plotting.label("relative error of dL/d" + param, ""))
            plotting.log_ticks(ax, "x", hs)
            plotting.log_ticks(ax, "y")
        fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside lower center", ncols=2)
        scenes = ", ".join(dict.fromkeys(CASE_SCENES[case].split()[0] for case, _ in keys))
        fig.suptitle(plotting.title(scenes, "ds", hs_all,
                                    "relative error of the loss gradient against the continuous-time derivative"))
    plotting.save(fig, path)


def plot_ball_sweep(path: Path) -> None:
    """Loss and derivative against e for the ball at h = 1e-3: the staircase, its
    discrete gradient, the event-aware gradient and the exact derivative."""
    h = 1e-3
    case = ball_case()
    es = np.linspace(0.8, 0.9, 201)
    curves = {}
    for adjoint in ("discrete", "event"):
        params, loss = case.ds_loss(h, adjoint)
        f = jax.jit(jax.vmap(jax.value_and_grad(lambda e: loss({**params, "e": e}))))
        curves[adjoint] = [np.asarray(a) for a in f(jnp.asarray(es))]
    exact = np.array([case.reference_loss("e", e) for e in es])
    exact_grad = np.array([central(lambda x: case.reference_loss("e", x), e, 1e-6) for e in es])
    unit = plotting.observable_unit("bouncing_ball", "z") + "^2"
    with plotting.style():
        fig, axes = plotting.figure(2, 1, panel=(6.4, 2.5), sharex=True)
        ax0, ax1 = axes[:, 0]
        ax0.plot(es, exact, "k-", lw=3, alpha=0.3, label="continuous time (exact)")
        ax0.plot(es, curves["discrete"][0], "C0-", lw=0.9, label=f"DS, h = {h:g} s")
        ax0.set_ylabel(plotting.label("loss L", unit))
        ax1.plot(es, exact_grad, "k-", lw=3, alpha=0.3, label="continuous time (exact)")
        ax1.plot(es, curves["discrete"][1], "C0-", lw=0.9, label="DS, discrete gradient")
        ax1.plot(es, curves["event"][1], "C3--", lw=1.1, label="DS, event-aware gradient")
        ax1.set_ylabel(plotting.label("dL/de", unit))
        for ax in (ax0, ax1):
            plotting.plain_ticks(ax, "x")
        for ax in (ax0, ax1):
            ax.legend(loc="upper left")  # the curves rise to the right
        plotting.bottom_labels(axes, plotting.label("restitution coefficient e", ""))
        fig.suptitle(plotting.title("bouncing_ball", "ds", h,
                                    "L: mean square mismatch of z over 1.5 s, data at e = 0.8"))
    plotting.save(fig, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", help="comma-separated cases (default: all)")
    ap.add_argument("--replot", action="store_true", help="redraw the convergence figure from the CSV")
    ap.add_argument("--ball-sweep", action="store_true",
                    help="recompute and draw the ball's loss and gradient against e only (about a minute)")
    args = ap.parse_args()
    if args.replot or args.ball_sweep:
        if args.replot:
            with open(RESULTS / "gradients.csv") as fh:
                plot_convergence(list(csv.DictReader(fh)), FIGURES / "event_gradients_convergence.png")
        if args.ball_sweep:
            plot_ball_sweep(FIGURES / "event_gradients_ball.png")
        return
    names = args.only.split(",") if args.only else list(CASES)
    RESULTS.mkdir(parents=True, exist_ok=True)
    FIGURES.mkdir(parents=True, exist_ok=True)
    path = RESULTS / "gradients.csv"
    rows = []
    if path.exists():
        with open(path) as fh:
            rows = [r for r in csv.DictReader(fh) if r["case"] not in names]
    for name in names:
        rows += study(CASES[name]())
    rows.sort(key=lambda r: (list(CASES).index(r["case"]), r["parameter"], -float(r["h"])))
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (RESULTS / "gradients.md").write_text(table(rows) + "\n")
    plot_convergence(rows, FIGURES / "event_gradients_convergence.png")
    if "ball" in names:
        plot_ball_sweep(FIGURES / "event_gradients_ball.png")
    print(table(rows))


if __name__ == "__main__":
    main()
