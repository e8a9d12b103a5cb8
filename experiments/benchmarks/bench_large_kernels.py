"""The kernels of a matrix-free step of the flexible cube, each against the
variant it replaced: the hex8 element force (closed form against
``jax.grad`` of the strain energy), the element stiffness (closed form
against ``jax.jacfwd`` of the force), the mass product (Kronecker form
against the node blocks) and a conjugate-gradient solve of the smooth
motion's block M + β' h² K (started from the preconditioned right-hand
side against jax's default start at zero, at the relative tolerances a
Newton update asks for, from a random right-hand side and from a smooth one
like Newton's residuals).

The variants of each kernel alternate, ``--repeats`` rounds, and the table
gives the median time of one call (compiled apart). Writes
``large_kernels.csv`` and ``large_kernels.md`` to ``--out``. Run it alone on
the machine:

    PYTHONPATH=$PWD python experiments/benchmarks/bench_large_kernels.py --divisions 10,20 --out docs/results/bench
"""

from __future__ import annotations

import argparse
import csv
import statistics
import sys
import time
from pathlib import Path

import jax

from nsga_jax._process_settings import configure_jax

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

import jax.numpy as jnp  # noqa: E402
import jax.scipy.sparse.linalg as jsp  # noqa: E402
import numpy as np  # noqa: E402

import nsga_jax  # noqa: E402
from nsga_jax._elements.hex8 import hex8_internal_force, hex8_stiffness, svk_energy  # noqa: E402
from nsga_jax._integrators.krylov import (  # noqa: E402
    MAX_STEPS,
    kronecker_mass,
    mass_preconditioner,
    on_range,
    projection,
)

H, BETA = 1e-4, 0.3
"""The step [s] and a coefficient β' of the smooth motion's block M + β' h² K."""


def timed(fn, *args) -> float:
    jax.block_until_ready(fn(*args))
    start = time.perf_counter()
    jax.block_until_ready(fn(*args))
    return time.perf_counter() - start


def interleaved(variants: dict, args: tuple, repeats: int) -> dict[str, float]:
    """Median seconds a call of each variant, the variants alternating."""
    compiled = {name: jax.jit(fn) for name, fn in variants.items()}
    for fn in compiled.values():
        jax.block_until_ready(fn(*args))
    times: dict[str, list[float]] = {name: [] for name in compiled}
    for _ in range(repeats):
        for name, fn in compiled.items():
            times[name].append(timed(fn, *args))
    return {name: statistics.median(t) for name, t in times.items()}


def cg_steps(matvec, b, precondition, rtol, x0) -> int:
    """Products a preconditioned CG solve takes (the start's product counted
    unless the start is zero, whose product XLA folds away)."""
    x, r = x0, b - matvec(x0)
    products, z = int(bool(jnp.any(x0 != 0))), precondition(r)
    p, rz = z, r @ z
    while jnp.linalg.norm(r) > rtol * jnp.linalg.norm(b) and products < MAX_STEPS:
        Ap = matvec(p)
        products += 1
        alpha = rz / (p @ Ap)
        x, r = x + alpha * p, r - alpha * Ap
        z = precondition(r)
        rz, rz_old = r @ z, rz
        p = z + (rz / rz_old) * p
    return products


def smooth_field(q0: jax.Array) -> jax.Array:
    """A smooth displacement of the nodes (n,), like the corrections Newton solves for."""
    X = q0.reshape(-1, 3)
    s = (X - X.min(0)) / (X.max(0) - X.min(0))
    return jnp.stack([jnp.sin(jnp.pi * s[:, 0]), jnp.cos(jnp.pi * s[:, 1]), s[:, 0] * s[:, 1] * s[:, 2]], 1).ravel()


def measure(divisions: int, repeats: int) -> list[dict]:
    scene = nsga_jax.load_scene("flexible_cube", {"divisions": divisions})
    model = scene.model
    rng = np.random.default_rng(0)
    q = jnp.asarray(scene.q0) + 1e-4 * jnp.asarray(rng.standard_normal(model.n_dof))
    group = model.bodies[0].elements
    xe, ve = group.gather(q), jnp.zeros((group.n_elements, 24))
    rows: list[dict] = []

    def add(kernel, result, note=""):
        for variant, seconds in result.items():
            rows.append({"divisions": divisions, "n_dof": model.n_dof, "kernel": kernel, "variant": variant,
                         "ms": round(1e3 * seconds, 3), "note": note})

    add("element force", interleaved({
        "jax.grad of the energy": lambda xe: -jax.vmap(jax.grad(svk_energy))(xe, group.params),
        "closed form": lambda xe: jax.vmap(hex8_internal_force)(xe, ve, group.params)}, (xe,), repeats))
    add("element stiffness", interleaved({
        "jax.jacfwd of the force": lambda xe: -jax.vmap(jax.jacfwd(hex8_internal_force))(xe, ve, group.params),
        "closed form": lambda xe: jax.vmap(hex8_stiffness)(xe, group.params)}, (xe,), repeats))
    M = model.element_mass(q).node_blocks()
    kron = kronecker_mass(model, jnp.float64)
    x = jnp.asarray(rng.standard_normal(model.n_dof))
    add("mass product", interleaved({"node blocks": lambda x: M.mv(x), "Kronecker": lambda x: kron.mv(x)},
                                    (x,), repeats))
    K = model.element_stiffness(q).node_blocks()
    A = M.combine(1.0, K, BETA * H**2)
    pre = mass_preconditioner(kron, 1.0)
    project = projection(model.constraint_rows(q))  # the bottom face, landed: every row active
    operators = {"free": (A.mv, pre.apply),
                 "projected on the landed face": (on_range(project, A.mv), on_range(project, pre.apply))}
    smooth = A.mv(smooth_field(jnp.asarray(scene.q0)))
    for block, (mv, apply) in operators.items():
        onto = (lambda v: v) if block == "free" else project
        for label, b in {"random": onto(x), "smooth": onto(smooth)}.items():
            for rtol in (1e-1, 1e-3, 1e-6):
                def solve(b, start, mv=mv, apply=apply, rtol=rtol):
                    x0 = apply(b) if start else jnp.zeros_like(b)
                    return jsp.cg(mv, b, x0=x0, tol=rtol, atol=0.0, maxiter=MAX_STEPS, M=apply)[0]
                products = {s: cg_steps(mv, b, apply, rtol, apply(b) if s else jnp.zeros_like(b))
                            for s in (False, True)}
                add(f"CG solve of M + β'h²K, {block}, {label} right-hand side, rtol {rtol:g}", interleaved(
                    {f"start 0 ({products[False]} products)": lambda b: solve(b, False),
                     f"start (c_m M)⁻¹ b ({products[True]} products)": lambda b: solve(b, True)}, (b,), repeats))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--divisions", default="10,20")
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--out", default="docs/results/bench")
    args = parser.parse_args()
    rows = [row for d in args.divisions.split(",") for row in measure(int(d), args.repeats)]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "large_kernels.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    from memory_peak import machine

    lines = [f"Kernels of a matrix-free step of the flexible cube, float64, median of {args.repeats} alternating "
             f"calls; bench_large_kernels.py --divisions {args.divisions}; {machine()}", "",
             "| divisions | n | kernel | variant | ms a call |", "|---|---|---|---|---|"]
    lines += [f"| {r['divisions']} | {r['n_dof']:,} | {r['kernel']} | {r['variant']} | {r['ms']} |" for r in rows]
    (out / "large_kernels.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
