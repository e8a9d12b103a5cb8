"""Block elimination against dense factorisations for a chain of N rigid
links (the chain of ``bench_chain.py``): where the switch pays, measured.

Two measurements, each interleaving the two solves:

- one Newton correction of the position sub-problem's bordered system at
  the chain's initial state (``StructuredFactorisation.bordered`` against
  ``linalg.solve_bordered`` on an LU factorisation), µs, the fastest of
  ``--repeats`` rounds of 300 calls;
- whole runs: 400 steps of 1 ms with DS, the block elimination on (its
  threshold ``MIN_BLOCKS`` set to 1) and off (set above N), µs per step, the
  fastest of ``--repeats`` runs of one compiled program each.

    python experiments/benchmarks/bench_structured.py [--links 6 8 12 16 20 50 100] [--out FILE]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

from nsga_jax._process_settings import configure_jax

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_chain import chain, write_table  # noqa: E402


def correction_us(model, q0, repeats: int) -> tuple[float, float]:
    """µs of one bordered correction: (block elimination, dense LU + Schur complement)."""
    import jax.numpy as jnp

    from nsga_jax._integrators import structured
    from nsga_jax._integrators.linalg import Factorisation, solve_bordered

    A, G = model.mass(q0), model.constraint_jacobian(q0)
    r1, r2 = jnp.ones(model.n_dof), jnp.ones(model.n_constraints)
    active = jnp.ones(model.n_constraints, bool)
    coupling = model.body_coupling

    @jax.jit
    def blocks(A, r1, r2, G):
        f = structured.StructuredFactorisation(matrix=A, K_norm=0.0, C_norm=0.0, coupling=coupling)
        return f.bordered(r1, r2, G, G, active, 1.0, 1.0)

    @jax.jit
    def dense(A, r1, r2, G):
        return solve_bordered(Factorisation.of(A, 0.0, 0.0), r1, r2, G, G, active, 1.0, 1.0)

    best = {blocks: float("inf"), dense: float("inf")}
    for fn in best:
        jax.block_until_ready(fn(A, r1, r2, G))
    for _ in range(repeats):
        for fn in best:  # interleaved
            start = time.perf_counter()
            for _ in range(300):
                out = fn(A, r1, r2, G)
            jax.block_until_ready(out)
            best[fn] = min(best[fn], (time.perf_counter() - start) / 300 * 1e6)
    return best[blocks], best[dense]


def run_us(model, q0, v0, structured_on: bool, steps: int, repeats: int) -> tuple[float, float, str]:
    """µs per step and compile [s] of DS with the block elimination on or off."""
    import nsga_jax as nj
    from nsga_jax._integrators import structured

    structured.MIN_BLOCKS = 1 if structured_on else 10**9
    structured.block_layout.cache_clear()
    jax.clear_caches()
    first = nj.simulate(model, nj.DS(), 0.0, steps * 1e-3, 1e-3, q0, v0)
    kinds = "/".join(k.__name__ for k in nj.DS().matrix_kinds(model))
    per_step = min(nj.simulate(model, nj.DS(), 0.0, steps * 1e-3, 1e-3, q0, v0).stats["us_per_step"]
                   for _ in range(repeats))
    return per_step, first.stats["compile_time_s"], kinds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--links", type=int, nargs="+", default=[6, 8, 12, 16, 20, 50, 100])
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", type=Path, default=Path("experiments/out/bench_structured.md"))
    args = parser.parse_args()
    header = ("| links | blocks | correction, blocks [µs] | correction, dense [µs] | DS step, blocks [µs] "
              "| DS step, dense [µs] | compile, blocks / dense [s] |")
    rows = []
    print(header, flush=True)
    from nsga_jax._integrators import structured

    for n in args.links:
        model, q0, v0 = chain(n)
        structured.MIN_BLOCKS = 1
        layout = structured.block_layout(model.body_coupling, model.n_constraints)
        blocks_us, dense_us = correction_us(model, q0, args.repeats)
        on = run_us(model, q0, v0, True, args.steps, args.repeats)
        off = run_us(model, q0, v0, False, args.steps, args.repeats)
        rows.append(f"| {n} | {layout.blocks} × {layout.unknowns.shape[1]} | {blocks_us:.0f} | {dense_us:.0f} | "
                    f"{on[0]:.0f} | {off[0]:.0f} | {on[1]:.1f} / {off[1]:.1f} |")
        print(rows[-1], flush=True)
    write_table(args.out, f"python experiments/benchmarks/bench_structured.py --links {' '.join(map(str, args.links))}",
                header, rows)


if __name__ == "__main__":
    main()
