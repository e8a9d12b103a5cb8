"""One solve with the bar's constant position matrix M + h² K (h = 1e-3): on its
diagonals (``Tridiagonal``, LAPACK's tridiagonal elimination) against a
product with its dense inverse, for a single run and for a batch of 64
members (``vmap``). Prints µs per solve (chained calls in a compiled loop,
best of 5)."""

import jax
import jax.numpy as jnp
import numpy as np

from nsga_jax.bench import per_call
from nsga_jax.integrators.linalg import Tridiagonal
from nsga_jax.scenes import load_scene


def main(batch: int = 64) -> None:
    scene = load_scene("impacting_bar")
    ops = scene.scheme().prepare(scene.model, 1e-3, 0.0)
    n = scene.model.n_dof
    inverse = jnp.linalg.inv(ops.M + 1e-6 * ops.K)
    band = ops.position_inv.band
    x = jnp.ones(n)
    single_tri = per_call(Tridiagonal(band).solve, x, 5, 2000)
    single_dense = per_call(lambda y: inverse @ y, x, 5, 2000)
    inverses = jnp.broadcast_to(inverse, (batch, n, n)) + 0.0
    bands = jnp.broadcast_to(band, (batch, *band.shape)) + 0.0
    xs = jnp.ones((batch, n))
    batch_tri = per_call(lambda y: jax.vmap(lambda b, v: Tridiagonal(b).solve(v))(bands, y), xs, 5, 200)
    batch_dense = per_call(lambda y: jax.vmap(lambda m, v: m @ v)(inverses, y), xs, 5, 200)
    print(f"single run: tridiagonal {1e6 * single_tri:.1f} us, dense inverse {1e6 * single_dense:.1f} us")
    print(f"batch of {batch}: tridiagonal {1e6 * batch_tri:.1f} us, dense inverses {1e6 * batch_dense:.1f} us")
    assert np.allclose(Tridiagonal(band).solve(x), inverse @ x, rtol=1e-8)


if __name__ == "__main__":
    main()
