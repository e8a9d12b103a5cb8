"""Which batched LU factorisations jaxlib's CPU kernel spreads over threads.

    python experiments/tools/lapack_batch_threads.py [--sizes 2,8,12,16,27] [--batches 8,16,32,64,128]

For each matrix size n and batch B, a compiled loop factors B matrices of
n × n (``jax.scipy.linalg.lu_factor``) 3e8 / (B n³) times (200 to 20,000) on one CPU
device, and prints the wall time per matrix and the CPU seconds its threads spent (from
``/proc/self/task``): all on the calling thread when each call runs there,
on XLA's intra-op pool threads (``tf_XLAEigen``) when the kernel split the
batch over them. A split call blocks its thread until the parts are done,
which is what deadlocks several host devices running such calls at once
(``nsga_jax._compat.bounded_lapack_batches`` keeps each call's
work, B n³, well below the smallest split seen here). Linux only.
"""

from __future__ import annotations

import argparse
import os
import time

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np

from nsga_jax._process_settings import configure_jax  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them


POOL = "tf_XLAEigen"
"""The name of XLA's CPU intra-op pool threads."""


def thread_cpu_seconds() -> dict[tuple[str, str], float]:
    """CPU seconds (user + system) so far of each thread of this process, by (id, name)."""
    tick = os.sysconf("SC_CLK_TCK")
    seconds = {}
    for tid in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{tid}/comm") as f:
                name = f.read().strip()
            with open(f"/proc/self/task/{tid}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()
        except OSError:  # the thread ended
            continue
        seconds[(tid, name)] = (int(fields[11]) + int(fields[12])) / tick
    return seconds


def cpu_by_pool(n: int, batch: int) -> tuple[float, float, float]:
    """(µs of wall time per matrix factored, CPU seconds on the intra-op pool's
    threads, on every other thread) of a loop of batched LU factorisations."""
    iters = min(20_000, max(200, int(3e8 / (batch * n**3))))
    A = jnp.asarray(np.random.default_rng(0).normal(size=(batch, n, n)) + n * np.eye(n))
    loop = jax.jit(lambda A: jax.lax.fori_loop(0, iters, lambda i, A: A + 1e-12 * jsl.lu_factor(A)[0], A))
    loop(A).block_until_ready()
    before, start = thread_cpu_seconds(), time.perf_counter()
    loop(A).block_until_ready()
    wall, after = time.perf_counter() - start, thread_cpu_seconds()
    pool = other = 0.0
    for key, seconds in after.items():
        spent = seconds - before.get(key, 0.0)
        if key[1] == POOL:
            pool += spent
        else:
            other += spent
    return 1e6 * wall / (iters * batch), pool, other


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="2,8,12,16,27")
    parser.add_argument("--batches", default="8,16,32,64,128")
    args = parser.parse_args()
    print(f"{'n':>4} {'batch':>6} {'work B n^3':>11} {'us/matrix':>10} {'pool cpu s':>11} {'other cpu s':>12}  split")
    for n in map(int, args.sizes.split(",")):
        for batch in map(int, args.batches.split(",")):
            us, pool, other = cpu_by_pool(n, batch)
            split = "yes" if pool > 0.1 * (pool + other) else "no"
            print(f"{n:4d} {batch:6d} {batch * n**3:11.3g} {us:10.2f} {pool:11.2f} {other:12.2f}  {split}",
                  flush=True)


if __name__ == "__main__":
    main()
