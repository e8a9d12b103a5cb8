"""Regenerate the figures of docs/newtons-cradle.md and docs/double-pendulum.md.

    python experiments/studies/scene_figures.py [--out docs/figures]

Each scene at its defaults with DS, against its exact (cradle) or
event-driven (double pendulum) reference; drawn with the package's figure
style (nsga_jax._plotting).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from nsga_jax import _plotting as plotting
from nsga_jax._exact_pendulums import double_pendulum, double_pendulum_energy
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import load_scene

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them


def cradle_figure(out: Path) -> None:
    scene = load_scene("newtons_cradle")
    sol = scene.run(progress=False)
    p, o, units = scene.parameters, sol.observables, scene.spec.units
    n = p["n_balls"]
    t_fine = np.linspace(0.0, scene.solver["t_end"], 2001)
    exact = scene.exact(t_fine)
    with plotting.style():
        fig, axes = plotting.figure(2, 2, panel=(4.2, 2.6), sharex=True)
        (ax1, ax2), (ax3, ax4) = axes
        for i in range(1, n + 1):
            ax1.plot(t_fine, exact[f"v{i}"], "k-", lw=3, alpha=0.2, label="exact" if i == 1 else None)
            ax1.plot(sol.ts, o[f"v{i}"], lw=1.0, color=f"C{i - 1}", label=f"ball {i}")
            ax2.plot(t_fine, 1e3 * (exact[f"x{i}"] - exact[f"x{i}"][0]), "k-", lw=3, alpha=0.2)
            ax2.plot(sol.ts, 1e3 * (o[f"x{i}"] - o[f"x{i}"][0]), lw=1.0, color=f"C{i - 1}")
        ax1.set_ylabel(plotting.label("velocity", units["v1"]))
        ax1.legend(loc="center right", fontsize=7)
        ax2.set_ylabel(plotting.label("displacement", "mm"))
        p0, e0 = p["mass"] * p["velocity"], 0.5 * p["mass"] * p["velocity"] ** 2
        ax3.semilogy(sol.ts, np.abs(o["momentum"] - p0) / p0 + 1e-17, lw=1.0, label="momentum")
        ax3.semilogy(sol.ts, np.abs(o["energy"] - e0) / e0 + 1e-17, lw=1.0, label="energy")
        ax3.set_ylabel(plotting.label("relative change", ""))
        ax3.legend(loc="center right")
        for i in range(1, n):
            ax4.plot(sol.ts, 1e3 * o[f"gap{i}"], lw=1.0, color=f"C{i - 1}", label=f"gap {i}–{i + 1}")
        ax4.set_ylabel(plotting.label("gap", "mm"))
        ax4.legend(loc="center right", fontsize=7)
        for ax in axes.flat:
            plotting.plain_ticks(ax, "x")
        plotting.bottom_labels(axes, "t [s]")
        fig.suptitle(plotting.title("newtons_cradle", scene.solver["scheme"], sol.h,
                                    f"{n} balls, e = {p['e']:g}, gaps {1e3 * p['gap']:g} mm, "
                                    f"v0 = {p['velocity']:g} m/s"))
    plotting.save(fig, out / "newtons_cradle.png")


def double_pendulum_figure(out: Path) -> None:
    hs = (2e-3, 5e-4)
    runs = {h: load_scene("double_pendulum", {"h": h}) for h in hs}
    sols = {h: scene.run(progress=False) for h, scene in runs.items()}
    scene = runs[hs[-1]]
    p, units = scene.parameters, scene.spec.units
    keys = ("m1", "m2", "l1", "l2", "gravity", "theta1", "theta2", "omega1", "omega2", "wall_x", "e")
    t_fine = np.linspace(0.0, scene.solver["t_end"], 4001)
    (th1, th2, w1, w2), impacts = double_pendulum(t_fine, *(p[k] for k in keys))
    scheme = scene.solver["scheme"].upper()
    with plotting.style():
        fig, axes = plotting.figure(2, 2, panel=(4.2, 2.6))
        (ax1, ax2), (ax3, ax4) = axes
        ax1.plot(t_fine, th1, "k-", lw=3, alpha=0.2, label="event-driven reference")
        ax1.plot(t_fine, th2, "k-", lw=3, alpha=0.2)
        for (h, sol), ls in zip(sols.items(), ("--", "-")):
            o = sol.observables
            ax1.plot(sol.ts, o["theta1"], ls, lw=1.0, color="C0", label=f"θ1, {scheme} h = {h:g} s")
            ax1.plot(sol.ts, o["theta2"], ls, lw=1.0, color="C1", label=f"θ2, {scheme} h = {h:g} s")
            (r1, r2, _, _), _ = double_pendulum(sol.ts, *(p[k] for k in keys))
            err = np.maximum(np.abs(o["theta1"] - r1), np.abs(o["theta2"] - r2))
            ax2.semilogy(sol.ts, err + 1e-16, lw=0.8, label=f"{scheme}, h = {h:g} s")
            ax4.plot(sol.ts, o["energy"], ls, lw=1.0, label=f"{scheme}, h = {h:g} s")
        for t_star in impacts[:, 0]:
            ax2.axvline(t_star, color="k", lw=0.6, ls=":")
        ax1.set_ylabel(plotting.label("angle", units["theta1"]))
        ax1.legend(loc="lower left", fontsize=6)
        ax2.set_ylabel(plotting.label("max(|θ1 − θ1,ref|, |θ2 − θ2,ref|)", units["theta1"]))
        ax2.set_title("error against the reference (dotted: impacts)", loc="left", fontsize=8)
        ax2.legend(loc="lower right", fontsize=7)
        o = sols[hs[-1]].observables
        x_tip = p["l1"] * np.sin(o["theta1"]) + p["l2"] * np.sin(o["theta2"])
        y_tip = -p["l1"] * np.cos(o["theta1"]) - p["l2"] * np.cos(o["theta2"])
        ax3.plot(x_tip, y_tip, lw=0.8, label=f"tip of rod 2, {scheme} h = {hs[-1]:g} s")
        ax3.axvline(p["wall_x"], color="k", lw=2, label=f"wall, x = {p['wall_x']:g} m")
        ax3.plot([0.0], [0.0], "ko", ms=3)
        ax3.set_aspect("equal", adjustable="datalim")
        ax3.set_xlabel(plotting.label("x", units["tip_x"]))
        ax3.set_ylabel(plotting.label("y", units["tip_x"]))
        ax3.legend(loc="upper right", fontsize=7)
        energy = double_pendulum_energy(th1, th2, w1, w2, *(p[k] for k in keys[:5]))
        ax4.plot(t_fine, energy, "k-", lw=3, alpha=0.2, label="reference")
        ax4.set_ylabel(plotting.label("energy", units["energy"]))
        ax4.legend(loc="upper right", fontsize=7)
        for ax in (ax1, ax2, ax4):
            ax.set_xlabel("t [s]")
            plotting.plain_ticks(ax, "x")
        fig.suptitle(plotting.title("double_pendulum", scene.solver["scheme"], list(hs),
                                    f"two rods pinned in series, tip against a wall, e = {p['e']:g}"))
    plotting.save(fig, out / "double_pendulum_rods.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("docs/figures"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    cradle_figure(args.out)
    double_pendulum_figure(args.out)
    print(f"wrote figures to {args.out}")


if __name__ == "__main__":
    main()
