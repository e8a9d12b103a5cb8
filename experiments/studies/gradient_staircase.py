"""What a gradient means through impacts: loss and gradient against the bouncing
ball's restitution e, discrete gradient vs finite differences vs the exact
continuous-time derivative.

    python experiments/studies/gradient_staircase.py

Loss: mean square mismatch of the height, sampled every 10 ms over 1.5 s (three
impacts), against the exact solution at e = 0.8. The DS loss is a fine
staircase in e: moving e moves the later impact instants, but on the discrete
grid an impact only jumps from one step to the next. The gradient nsga_jax
returns is the exact derivative of the smooth piece (the active set frozen:
impacts stay at their steps); it matches finite differences with a small step
and misses the impact-time part of the derivative, which finite differences over
many pieces and the continuous-time derivative contain.
Writes docs/figures/gradient_ball_staircase.png and
docs/results/gradients/ball_staircase.{csv,md}.
"""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import nsga_jax  # noqa: E402
from nsga_jax import _plotting as plotting  # noqa: E402
from nsga_jax._exact import bouncing_ball  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import parametrize  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

T_END, E_TRUE, G, H0 = 1.5, 0.8, 9.81, 1.0
T_DATA = np.arange(0.0, T_END + 1e-12, 0.01)
Z_DATA = bouncing_ball(T_DATA, H0, 0.0, G, E_TRUE)[0]
FIGURE = Path("docs/figures/gradient_ball_staircase.png")
RESULTS = Path("docs/results/gradients")


def exact_loss(e: float) -> float:
    return float(np.mean((bouncing_ball(T_DATA, H0, 0.0, G, e)[0] - Z_DATA) ** 2))


def exact_derivative(e: float, step: float = 1e-6) -> float:
    return (exact_loss(e + step) - exact_loss(e - step)) / (2 * step)


def discrete_loss(h: float):
    """``value_and_grad`` of the DS loss in e (vmappable), at step h."""
    n = int(round(T_END / h))
    params, build = parametrize("bouncing_ball", {"h": h, "height": H0}, ["e"])
    ts = jnp.arange(n + 1) * h

    def loss(e):
        model, q0, v0, observables = build({"e": e})
        z = observables(nsga_jax.integrate(model, nsga_jax.DS(), 0.0, n * h, h, q0, v0, n_steps=n))["z"]
        return jnp.mean((jnp.interp(T_DATA, ts, z) - Z_DATA) ** 2)

    return jax.jit(jax.vmap(jax.value_and_grad(loss)))


def main() -> None:
    hs = (1e-3, 1e-4)
    es = np.linspace(0.7, 0.9, 801)
    zoom = np.linspace(0.85, 0.851, 201)
    scans = {}
    for h in hs:
        f = discrete_loss(h)
        scans[h] = [tuple(np.asarray(a) for a in f(jnp.asarray(x))) for x in (es, zoom)]
    exact = np.array([exact_loss(e) for e in es])
    exact_grad = np.array([exact_derivative(e) for e in es])

    unit = plotting.observable_unit("bouncing_ball", "z") + "^2"
    looks = {1e-3: dict(color="C0", ls="-", lw=1.5), 1e-4: dict(color="C1", ls="--", lw=1.0)}
    exact_look = dict(color="k", ls="-", lw=3, alpha=0.25)
    e_label = plotting.label("restitution coefficient e", "")
    with plotting.style():
        fig, axes = plotting.figure(3, 1, panel=(6.6, 2.5))
        ax = axes[0, 0]
        ax.plot(es, exact, label="continuous time (exact)", **exact_look)
        for h in hs:
            ax.plot(es, scans[h][0][0], label=f"DS, h = {h:g} s", **looks[h])
        ax.set_ylabel(plotting.label("loss L", unit))
        ax.set_title("loss against e", loc="left")
        ax.legend(loc="upper center")
        ax = axes[1, 0]
        milli = 1e3  # the zoom's loss in 10^-3 m^2, not with an offset multiplier over the axis
        ax.plot(zoom, milli * np.array([exact_loss(e) for e in zoom]), label="continuous time (exact)",
                **exact_look)
        ax.plot(zoom, milli * scans[1e-3][1][0], ".-", ms=2, lw=0.8, color="C0", label="DS, h = 0.001 s")
        ax.set_ylabel(plotting.label("loss L", "10^-3 " + unit))
        ax.set_title("zoom: a staircase of smooth pieces (an impact instant jumps one step)", loc="left")
        ax.legend(loc="lower right")
        ax = axes[2, 0]
        ax.plot(es, exact_grad, label="exact dL/de", **exact_look)
        for h in hs:
            values, grads = scans[h][0]
            ax.plot(es, grads, label=f"nsga_jax gradient, h = {h:g} s", **looks[h])
        values = scans[1e-3][0][0]
        wide = 20  # points: a central difference over 2 * 20 * 2.5e-4 = 0.01 in e
        fd_wide = (values[2 * wide:] - values[:-2 * wide]) / (es[2 * wide:] - es[:-2 * wide])
        ax.plot(es[wide:-wide], fd_wide, ":", color="C2", lw=1.6,
                label="FD of the loss, step 5e-3, h = 0.001 s")
        ax.set_ylabel(plotting.label("dL/de", unit))
        ax.set_title("derivative against e", loc="left")
        ax.legend(loc="upper left")
        for ax in axes[:, 0]:
            ax.set_xlabel(e_label)
            plotting.plain_ticks(ax, "x")
        fig.suptitle(plotting.title("bouncing_ball", "ds", hs, f"L: mean square mismatch of z over {T_END:g} s "
                                    f"against the exact solution at e = {E_TRUE:g}"))
    FIGURE.parent.mkdir(parents=True, exist_ok=True)
    plotting.save(fig, FIGURE)

    # table: at a few e, the gradient, central differences with small and large steps, exact
    rows = []
    for e in (0.75, 0.85):
        for h in hs:
            f = discrete_loss(h)
            small, large = 1e-7, 5e-3
            points = jnp.asarray([e, e + small, e - small, e + large, e - large])
            values, grads = (np.asarray(a) for a in f(points))
            rows.append({"e": e, "h": h, "gradient": grads[0],
                         "fd_small": (values[1] - values[2]) / (2 * small),
                         "fd_large": (values[3] - values[4]) / (2 * large),
                         "exact": exact_derivative(e)})
    RESULTS.mkdir(parents=True, exist_ok=True)
    keys = list(rows[0])
    with open(RESULTS / "ball_staircase.csv", "w") as fh:
        fh.write(",".join(keys) + "\n")
        for r in rows:
            fh.write(",".join(f"{r[k]:.8g}" for k in keys) + "\n")
    md = ["| e | h [s] | nsga_jax gradient | FD, step 1e-7 | FD, step 5e-3 | exact dL/de |",
          "|---|---|---|---|---|---|"]
    md += [f"| {r['e']:g} | {r['h']:g} | {r['gradient']:.4f} | {r['fd_small']:.4f} | {r['fd_large']:.4f} | "
           f"{r['exact']:.4f} |" for r in rows]
    (RESULTS / "ball_staircase.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))
    print(f"wrote {FIGURE}")


if __name__ == "__main__":
    main()
