"""Ways of writing one block-tridiagonal solve (p blocks of s × s), timed
against each other, interleaved, on a CPU:

- ``augmented`` (what ``solve_block_tridiagonal`` does): each step one
  Gauss–Jordan elimination of [S_i | U_i | b_i'];
- ``inverse``: each step a Gauss–Jordan inverse of S_i, then S_i⁻¹ U_i and
  S_i⁻¹ b_i' as products (how the solve was written before);
- ``one update``: the augmented step with each pivot one elementwise update,
  [S | B] - c e_kᵀ [S | B] with c_i = S_ik / S_kk (c_k = 1 - 1 / S_kk), in
  place of a row division and an update;
- ``both ends``: the augmented step eliminating from the first and the last
  block at once (two half-length sweeps batched together), meeting in the
  middle block.

Random block-diagonally dominant systems; µs per solve, the fastest of
``--repeats`` rounds of 100 chained calls, single and in a batch (``vmap``);
compile seconds; the largest difference from the ``augmented`` solution.
With ``--chain``, also whole DS runs of the chain of ``bench_chain.py`` on
the block elimination (400 steps of 1 ms), the step written both ways
(``augmented`` and ``inverse``), alternating in one process.

    python experiments/benchmarks/bench_block_elimination.py [--blocks 20 50 100] [--chain 50 100] [--out FILE]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from nsga_jax._process_settings import configure_jax

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

from nsga_jax._integrators import block_tridiagonal as bt  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_chain import chain, write_table  # noqa: E402


def _inverse(a: jax.Array) -> jax.Array:
    """Gauss–Jordan inverse of one block, elementwise, without pivoting."""
    s = a.shape[-1]
    inv = jnp.eye(s, dtype=a.dtype)
    row = jnp.arange(s)[:, None]
    for k in range(s):
        pivot = a[k:k + 1, k:k + 1]
        a_k, inv_k = a[k:k + 1, :] / pivot, inv[k:k + 1, :] / pivot
        column = a[:, k:k + 1]
        a = jnp.where(row == k, a_k, a - column * a_k)
        inv = jnp.where(row == k, inv_k, inv - column * inv_k)
    return inv


def _sweep(step, diag, coupled_prev, coupled_next, rhs):
    """The down sweep: (W_i, y_i) for each block, shapes (p, s, s) and (p, s)."""
    s = diag.shape[-1]
    start = (jnp.zeros((s, s), diag.dtype), jnp.zeros((s,), rhs.dtype))
    return jax.lax.scan(lambda carry, blocks: (step(carry, blocks),) * 2, start,
                        (diag, coupled_prev, coupled_next, rhs))[1]


def _back(W, y, x_end):
    return jax.lax.scan(lambda x_next, wy: (wy[1] - bt._mv(wy[0], x_next),) * 2, x_end, (W, y), reverse=True)[1]


def _augmented_step(carry, blocks):
    (W, y), (D, L, U, b) = carry, blocks
    s = D.shape[-1]
    e = bt.gauss_jordan(jnp.concatenate([D - bt._mm(L, W), U, (b - bt._mv(L, y))[:, None]], axis=1))
    return e[:, :s], e[:, s]


def _inverse_step(carry, blocks):
    (W, y), (D, L, U, b) = carry, blocks
    S_inv = _inverse(D - bt._mm(L, W))
    return bt._mm(S_inv, U), bt._mv(S_inv, b - bt._mv(L, y))


def _one_update_step(carry, blocks):
    (W, y), (D, L, U, b) = carry, blocks
    s = D.shape[-1]
    augmented = jnp.concatenate([D - bt._mm(L, W), U, (b - bt._mv(L, y))[:, None]], axis=1)
    rows = jnp.arange(s)
    for k in range(s):
        pivot = augmented[k, k]
        c = jnp.where(rows == k, 1.0 - 1.0 / pivot, augmented[:, k] / pivot)
        augmented = augmented - c[:, None] * augmented[k][None, :]
    return augmented[:, s:2 * s], augmented[:, 2 * s]


def _one_way(step):
    def solve(diag, lower, upper, rhs):
        s = diag.shape[-1]
        zero = jnp.zeros((1, s, s), diag.dtype)
        W, y = _sweep(step, diag, jnp.concatenate([zero, lower]), jnp.concatenate([upper, zero]), rhs)
        return _back(W, y, jnp.zeros((s,), rhs.dtype))
    return solve


def both_ends(diag, lower, upper, rhs):
    """Eliminate from both ends at once (reversing the blocks swaps L and U)."""
    p, s = diag.shape[0], diag.shape[-1]
    if p % 2 == 0:  # one decoupled identity block below makes p odd
        diag = jnp.concatenate([diag, jnp.eye(s, dtype=diag.dtype)[None]])
        lower, upper = (jnp.concatenate([x, jnp.zeros((1, s, s), x.dtype)]) for x in (lower, upper))
        rhs = jnp.concatenate([rhs, jnp.zeros((1, s), rhs.dtype)])
    m = (diag.shape[0] - 1) // 2
    zero = jnp.zeros((1, s, s), diag.dtype)
    top = (diag[:m], jnp.concatenate([zero, lower[:m - 1]]), upper[:m], rhs[:m])
    bottom = (diag[::-1][:m], jnp.concatenate([zero, upper[::-1][:m - 1]]), lower[::-1][:m], rhs[::-1][:m])
    W, y = jax.vmap(lambda *a: _sweep(_augmented_step, *a))(*(jnp.stack(pair) for pair in zip(top, bottom)))
    S = diag[m] - bt._mm(lower[m - 1], W[0, -1]) - bt._mm(upper[m], W[1, -1])
    b = rhs[m] - bt._mv(lower[m - 1], y[0, -1]) - bt._mv(upper[m], y[1, -1])
    x_m = bt.gauss_jordan(jnp.concatenate([S, b[:, None]], axis=1))[:, 0]
    halves = jax.vmap(_back, in_axes=(0, 0, None))(W, y, x_m)
    return jnp.concatenate([halves[0], x_m[None], halves[1][::-1]])[:p]


VARIANTS = {"augmented": bt.solve_block_tridiagonal, "inverse": _one_way(_inverse_step),
            "one update": _one_way(_one_update_step), "both ends": both_ends}


def random_system(p: int, s: int, batch: int | None, seed: int = 0):
    rng = np.random.default_rng(seed)
    lead = () if batch is None else (batch,)
    diag = rng.normal(size=lead + (p, s, s)) * 0.1 + 4 * np.eye(s)
    lower, upper = rng.normal(size=(2,) + lead + (p - 1, s, s)) * 0.1
    return [jnp.asarray(x) for x in (diag, lower, upper, rng.normal(size=lead + (p, s)))]


def time_solves(p: int, s: int, batch: int | None, repeats: int) -> dict[str, tuple[float, float, float]]:
    """{variant: (µs per solve, compile [s], max |x - x_augmented|)}."""
    args = random_system(p, s, batch)
    fns, compile_s, out = {}, {}, {}
    for name, solve in VARIANTS.items():
        fns[name] = jax.jit(solve if batch is None else jax.vmap(solve))
        start = time.perf_counter()
        out[name] = jax.block_until_ready(fns[name](*args))
        compile_s[name] = time.perf_counter() - start
    best = dict.fromkeys(fns, float("inf"))
    for _ in range(repeats):
        for name, fn in fns.items():  # interleaved
            start = time.perf_counter()
            for _ in range(100):
                x = fn(*args)
            jax.block_until_ready(x)
            best[name] = min(best[name], (time.perf_counter() - start) / 100 * 1e6)
    return {name: (best[name], compile_s[name], float(jnp.max(jnp.abs(out[name] - out["augmented"]))))
            for name in fns}


def time_chain(links: int, repeats: int, steps: int = 400) -> dict[str, tuple[float, jax.Array]]:
    """{variant: (µs per step, final q)} of DS on the chain, the solve written as ``augmented`` / ``inverse``."""
    import nsga_jax as nj
    from nsga_jax._integrators import structured

    model, q0, v0 = chain(links)
    saved = structured.MIN_BLOCKS
    runs = {}
    try:
        structured.MIN_BLOCKS = 1  # the block elimination at any number of links
        structured.block_layout.cache_clear()
        assert structured.Structured in nj.DS().matrix_kinds(model), "the chain must take the block elimination"
        for name in ("augmented", "inverse"):  # each its own compiled program
            structured.solve_block_tridiagonal = VARIANTS[name]
            jax.clear_caches()
            run = jax.jit(lambda q, v: nj.integrate(model, nj.DS(), 0.0, steps * 1e-3, 1e-3, q, v,
                                                   saveat=nj.SaveAt(every=steps)).q[-1])
            jax.block_until_ready(run(q0, v0))
            runs[name] = run
    finally:
        structured.solve_block_tridiagonal, structured.MIN_BLOCKS = VARIANTS["augmented"], saved
        structured.block_layout.cache_clear()
    best, final = dict.fromkeys(runs, float("inf")), {}
    for _ in range(repeats):
        for name, run in runs.items():  # interleaved
            start = time.perf_counter()
            final[name] = jax.block_until_ready(run(q0, v0))
            best[name] = min(best[name], (time.perf_counter() - start) / steps * 1e6)
    return {name: (best[name], final[name]) for name in runs}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blocks", type=int, nargs="+", default=[20, 50, 100])
    parser.add_argument("--size", type=int, default=6)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--chain", type=int, nargs="*", default=[50, 100])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", type=Path, default=Path("experiments/out/bench_block_elimination.md"))
    args = parser.parse_args()
    names = list(VARIANTS)
    header = ("| what | blocks | " + " | ".join(f"{n} [µs]" for n in names) + " | "
              + " | ".join(f"compile, {n} [s]" for n in names) + " | max difference |")
    rows = []
    print(header, flush=True)
    for batch in (None, args.batch):
        for p in args.blocks:
            t = time_solves(p, args.size, batch, args.repeats)
            what = "one solve" if batch is None else f"batch of {batch}"
            rows.append(f"| {what} | {p} × {args.size} | " + " | ".join(f"{t[n][0]:.0f}" for n in names) + " | "
                        + " | ".join(f"{t[n][1]:.2f}" for n in names) + f" | {max(t[n][2] for n in names):.1e} |")
            print(rows[-1], flush=True)
    for links in args.chain:
        t = time_chain(links, args.repeats)
        diff = float(jnp.max(jnp.abs(t["augmented"][1] - t["inverse"][1])))
        rows.append(f"| DS step, chain | {links} links | {t['augmented'][0]:.0f} | {t['inverse'][0]:.0f} | "
                    + " | ".join("–" for _ in range(2 * len(names) - 2)) + f" | {diff:.1e} |")
        print(rows[-1], flush=True)
    write_table(args.out, "python experiments/benchmarks/bench_block_elimination.py", header, rows)


if __name__ == "__main__":
    main()
