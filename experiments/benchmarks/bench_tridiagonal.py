"""One solve with the bar's constant position matrix M + h² K (h = 1e-3, n = 201),
three ways: nsga_jax's block elimination (``Tridiagonal``, what the stepper
uses), LAPACK's tridiagonal elimination (``lax.linalg.tridiagonal_solve``,
pivoting, one library call per solve) and a product with the dense inverse;
for a single run and for a batch of members (``vmap``). Prints µs per solve
(chained calls in a compiled loop, best of 5, three measurements each) and
checks that the three agree.

    python experiments/benchmarks/bench_tridiagonal.py [--batch 64]
"""

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from nsga_jax._bench import per_call  # noqa: E402
from nsga_jax._integrators.linalg import Tridiagonal, band_matrix  # noqa: E402
from nsga_jax._process_settings import configure_jax  # noqa: E402
from nsga_jax.scenes import load_scene  # noqa: E402

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them


def lapack(band, rhs):
    return jax.lax.linalg.tridiagonal_solve(band[0], band[1], band[2], rhs[:, None])[:, 0]


def main(batch: int = 64) -> None:
    scene = load_scene("impacting_bar")
    ops = eqx.filter_jit(lambda h: scene.scheme().prepare(scene.model, h, 0.0))(1e-3)
    n = scene.model.n_dof
    A = ops.mass.M + 1e-6 * ops.force.K
    inverse, band = jnp.linalg.inv(A), band_matrix(A, 1)
    blocks = eqx.filter_jit(Tridiagonal.of)(band)
    x = jnp.asarray(np.random.default_rng(0).normal(size=n))
    ref = np.linalg.solve(np.asarray(A), np.asarray(x))
    for name, fn in (("block elimination", blocks.solve), ("LAPACK", lambda y: lapack(band, y)),
                     ("dense inverse", lambda y: inverse @ y)):
        err = np.abs(np.asarray(fn(x)) - ref).max() / np.abs(ref).max()
        assert err < 1e-12, (name, err)
        times = [1e6 * per_call(fn, x, 5, 2000) for _ in range(3)]
        print(f"single run, {name}: {' / '.join(f'{t:.1f}' for t in times)} us per solve (error {err:.0e})")

    stack = lambda a: jnp.broadcast_to(a, (batch, *a.shape)) + 0.0  # noqa: E731
    members = jax.tree_util.tree_map(stack, blocks)
    inverses, bands = stack(inverse), stack(band)
    xs = jnp.ones((batch, n))
    for name, fn in (("block elimination", lambda y: jax.vmap(lambda t, v: t.solve(v))(members, y)),
                     ("LAPACK", lambda y: jax.vmap(lapack)(bands, y)),
                     ("dense inverses", lambda y: jax.vmap(lambda m, v: m @ v)(inverses, y))):
        times = [1e6 * per_call(fn, xs, 5, 200) for _ in range(3)]
        print(f"batch of {batch}, {name}: {' / '.join(f'{t:.0f}' for t in times)} us per batch solve")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=64)
    main(parser.parse_args().batch)
