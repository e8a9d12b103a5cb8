"""Regenerate the figures of README.md and docs/accuracy.md (about half a minute on 2 cores).

    python experiments/studies/readme_figures.py [--out docs/figures]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from nsga_jax.exact import bouncing_ball  # noqa: E402
from nsga_jax.metrics import observed_order, relative_l1_error  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402


def bar_figure(out: Path) -> None:
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    for h, style in ((1e-2, "--"), (1e-3, "-")):
        sol = load_scene("impacting_bar", {"h": h}).run()
        o = sol.observables
        for ax, key in zip(axes.flat, ("tip_gap", "tip_force", "node045_u", "node045_v")):
            ax.plot(sol.ts, o[key], style, lw=1.0, label=f"DS, h = {h:g} s")
            ax.set_ylabel(key)
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    for ax in axes[1]:
        ax.set_xlabel("t [s]")
    axes[0, 1].legend()
    fig.suptitle("Elastic bar hitting a wall (paper §4.2): tip gap, contact force Λ/h, node 0.45 m from the tip")
    fig.tight_layout()
    fig.savefig(out / "impacting_bar.png", dpi=100)
    plt.close(fig)


def ball_figure(out: Path) -> None:
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6))
    t = np.linspace(0, 3, 3001)
    ax1.plot(t, bouncing_ball(t, 1.0, 0.0, 9.81, 0.8)[0], "k-", lw=2, alpha=0.3, label="exact")
    hs, errors = [1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4], []
    for h in hs:
        sol = load_scene("bouncing_ball", {"h": h, "t_end": 3.0}).run()
        errors.append(relative_l1_error(sol.q[:, 0], bouncing_ball(sol.ts, 1.0, 0.0, 9.81, 0.8)[0]))
        if h in (1e-2, 1e-3):
            ax1.plot(sol.ts, sol.q[:, 0], lw=1, label=f"DS, h = {h:g} s")
    ax1.set_xlabel("t [s]")
    ax1.set_ylabel("z [m]")
    ax1.legend()
    ax1.grid(alpha=0.3)
    ax2.loglog(hs, errors, "o-", label=f"DS, observed order {observed_order(hs, errors):.2f}")
    ax2.loglog(hs, errors[0] * np.asarray(hs) / hs[0], "k:", label="slope 1")
    ax2.set_xlabel("h [s]")
    ax2.set_ylabel("error of z (eq. 52)")
    ax2.legend()
    ax2.grid(alpha=0.3, which="both")
    fig.suptitle("Bouncing ball (e = 0.8) against the exact solution")
    fig.tight_layout()
    fig.savefig(out / "bouncing_ball.png", dpi=100)
    plt.close(fig)


def pendulum_figure(out: Path) -> None:
    scene = load_scene("rigid_pendulum", {"t_end": 10.0})
    sol = scene.run()
    o = sol.observables
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(12, 3.4))
    ax1.plot(o["x"], o["y"], lw=0.8)
    ax1.axvline(scene.parameters["wall_x"], color="k", lw=2)
    ax1.set_aspect("equal")
    ax1.set_xlabel("x [m]")
    ax1.set_ylabel("y [m]")
    ax2.semilogy(sol.ts, np.abs(o["constraint"]) + 1e-17, lw=0.8, label="position |√(x²+y²) − l|")
    radial = np.abs((sol.q * sol.v).sum(axis=1)) / scene.parameters["length"]
    ax2.semilogy(sol.ts, radial + 1e-17, lw=0.8, label="velocity |g_q v|")
    ax2.set_xlabel("t [s]")
    ax2.set_ylabel("rod constraint violation")
    ax2.legend(fontsize=8)
    ax3.plot(sol.ts, o["energy"], lw=1)
    ax3.set_xlabel("t [s]")
    ax3.set_ylabel("energy [J]")
    for ax in (ax1, ax2, ax3):
        ax.grid(alpha=0.3)
    fig.suptitle(f"Rigid pendulum against a wall (e = {scene.parameters['e']}), h = 1e-3 s, 10⁴ steps")
    fig.tight_layout()
    fig.savefig(out / "rigid_pendulum.png", dpi=100)
    plt.close(fig)


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
