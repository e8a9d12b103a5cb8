"""Regenerate the figures of README.md and docs/accuracy.md (about half a minute on 2 cores).

    python experiments/studies/readme_figures.py [--out docs/figures]

Drawn with the package's figure style (nsga_jax._plotting): units from each
scene's SceneSpec.units, titles naming the scene, the scheme and h.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from nsga_jax import _plotting as plotting
from nsga_jax._exact import bouncing_ball
from nsga_jax._metrics import observed_order, relative_l1_error
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import REGISTRY, load_scene

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

BAR_QUANTITIES = {
    "tip_gap": "tip gap",
    "tip_force": "contact force Λ/h",
    "node045_u": "displacement of node045",
    "node045_v": "velocity of node045",
}


def bar_figure(out: Path) -> None:
    units = REGISTRY["impacting_bar"].units
    runs = {h: load_scene("impacting_bar", {"h": h}) for h in (1e-2, 1e-3)}
    sols = {h: scene.run() for h, scene in runs.items()}
    scheme = runs[1e-2].solver["scheme"]
    with plotting.style():
        fig, axes = plotting.figure(2, 2, panel=(4.2, 2.6), sharex=True)
        for (h, sol), look in zip(sols.items(), (dict(ls="--", lw=1.3), dict(ls="-", lw=0.9))):
            for ax, key in zip(axes.flat, BAR_QUANTITIES):
                ax.plot(sol.ts, sol.observables[key], label=f"{scheme.upper()}, h = {h:g} s", **look)
        for ax, (key, quantity) in zip(axes.flat, BAR_QUANTITIES.items()):
            ax.set_ylabel(plotting.label(quantity, units[key]))
            plotting.plain_ticks(ax, "x")
        plotting.bottom_labels(axes, "t [s]")
        plotting.figure_legend(fig, axes)
        fig.suptitle(plotting.title("impacting_bar", scheme, list(sols),
                                    "elastic bar hitting a wall (paper §4.2); node045: 0.45 m from the tip"))
    plotting.save(fig, out / "impacting_bar.png")


def ball_figure(out: Path) -> None:
    units = REGISTRY["bouncing_ball"].units
    t = np.linspace(0, 3, 3001)
    hs, errors, shown = [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4], [], {}
    scheme = ""
    for h in hs:
        scene = load_scene("bouncing_ball", {"h": h, "t_end": 3.0})
        scheme = scene.solver["scheme"]
        e = scene.parameters["e"]
        sol = scene.run()
        errors.append(relative_l1_error(sol.q[:, 0], bouncing_ball(sol.ts, 1.0, 0.0, 9.81, 0.8)[0]))
        if h in (1e-2, 1e-3):
            shown[h] = sol
    with plotting.style():
        fig, axes = plotting.figure(1, 2, panel=(4.6, 3.0))
        ax1, ax2 = axes[0]
        ax1.plot(t, bouncing_ball(t, 1.0, 0.0, 9.81, 0.8)[0], "k-", lw=3, alpha=0.25, label="exact")
        for (h, sol), ls in zip(shown.items(), ("--", "-")):
            ax1.plot(sol.ts, sol.q[:, 0], ls, lw=1.0, label=f"{scheme.upper()}, h = {h:g} s")
        ax1.set_xlabel("t [s]")
        ax1.set_ylabel(plotting.label("height z", units["z"]))
        ax1.set_title("trajectory", loc="left")
        ax1.legend(loc="upper right")
        order = observed_order(hs, errors)
        ax2.loglog(hs, errors, "o-", mfc="none", label=f"{scheme.upper()}, observed order {order:.2f}")
        ax2.loglog(hs, errors[0] * np.asarray(hs) / hs[0], "k:", label="slope 1")
        plotting.log_ticks(ax2, "x", hs)
        plotting.log_ticks(ax2, "y")
        ax2.set_xlabel("h [s]")
        ax2.set_ylabel(plotting.label("error of z (eq. 52)", ""))
        ax2.set_title("convergence against the exact solution", loc="left")
        ax2.legend(loc="lower right")
        fig.suptitle(plotting.title("bouncing_ball", scheme, hs, f"e = {e:g}, dropped from 1 m, t = 0 ... 3 s"))
    plotting.save(fig, out / "bouncing_ball.png")


def pendulum_figure(out: Path) -> None:
    scene = load_scene("rigid_pendulum", {"t_end": 10.0})
    units = scene.spec.units
    sol = scene.run()
    o = sol.observables
    length, wall = scene.parameters["length"], scene.parameters["wall_x"]
    with plotting.style():
        fig, axes = plotting.figure(2, 2, panel=(4.2, 2.5))
        (ax1, ax2), (ax3, ax4) = axes
        ax1.plot(o["x"], o["y"], lw=0.8, label="path of the mass")
        ax1.axvline(wall, color="k", lw=2, label=f"wall, x = {wall:g} m")
        ax1.set_aspect("equal", adjustable="datalim")
        ax1.set_xlabel(plotting.label("x", units["x"]))
        ax1.set_ylabel(plotting.label("y", units["y"]))
        ax1.legend(loc="upper center")
        ax2.plot(sol.ts, o["energy"], lw=1.0)
        ax2.set_xlabel("t [s]")
        ax2.set_ylabel(plotting.label("energy", units["energy"]))
        ax3.semilogy(sol.ts, np.abs(o["constraint"]) + 1e-17, lw=0.6)
        ax3.set_xlabel("t [s]")
        ax3.set_ylabel(plotting.label("|√(x²+y²) − l|", units["constraint"]))
        ax3.set_title("rod constraint violation, position level", loc="left")
        radial = np.abs((sol.q * sol.v).sum(axis=1)) / length
        ax4.semilogy(sol.ts, radial + 1e-17, lw=0.6, color="C1")
        ax4.set_xlabel("t [s]")
        ax4.set_ylabel(plotting.label("|g_q v|", units["vx"]))
        ax4.set_title("rod constraint violation, velocity level", loc="left")
        for ax in (ax2, ax3, ax4):
            plotting.plain_ticks(ax, "x")
        fig.suptitle(plotting.title("rigid_pendulum", scene.solver["scheme"], sol.h,
                                    f"mass on a rigid rod against a wall, e = {scene.parameters['e']:g}, "
                                    f"{sol.n_steps} steps"))
    plotting.save(fig, out / "rigid_pendulum.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    bar_figure(args.out)
    ball_figure(args.out)
    pendulum_figure(args.out)
    print(f"wrote figures to {args.out}")


if __name__ == "__main__":
    main()
