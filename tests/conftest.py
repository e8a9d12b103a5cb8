import jax
import numpy as np
import pytest

import nsga_jax  # noqa: F401  (turns on float64)

jax.config.update("jax_enable_x64", True)


@pytest.fixture(autouse=True)
def _seed():
    np.random.seed(0)
