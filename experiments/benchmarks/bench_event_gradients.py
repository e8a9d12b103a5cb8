"""Cost of the event-aware gradient against the discrete one: value_and_grad of
the 200-element bar's mean square tip displacement over 1500 steps (h = 1e-3),
compile time apart, minimum of 3.

    python experiments/benchmarks/bench_event_gradients.py
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import nsga_jax  # noqa: E402
from nsga_jax._adjoint import adjoint_named  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import parametrize  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them

H, N = 1e-3, 1500


def main() -> None:
    params, build = parametrize("impacting_bar", {"h": H}, ["E", "e"])

    def loss(p, adjoint):
        model, q0, v0, observables = build(p)
        sol = nsga_jax.integrate(model, nsga_jax.DS(), 0.0, N * H, H, q0, v0, n_steps=N,
                                 adjoint=adjoint_named(adjoint))
        return jnp.mean(observables(sol)["tip_u"] ** 2)

    for adjoint in ("discrete", "event"):
        f = jax.jit(jax.value_and_grad(loss), static_argnums=1)
        t = time.perf_counter()
        jax.block_until_ready(f(params, adjoint))
        first = time.perf_counter() - t
        times = []
        for _ in range(3):
            t = time.perf_counter()
            jax.block_until_ready(f(params, adjoint))
            times.append(time.perf_counter() - t)
        print(f"{adjoint}: first call (compile + run) {first:.1f} s; value_and_grad {min(times):.3f} s")


if __name__ == "__main__":
    main()
