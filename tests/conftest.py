import os

import jax
import numpy as np
import pytest

import nsga_jax  # noqa: F401  (turns on float64)
from nsga_jax.compilation_cache import ENV

jax.config.update("jax_enable_x64", True)


@pytest.fixture(autouse=True)
def _seed():
    np.random.seed(0)


@pytest.fixture(autouse=True, scope="session")
def _compilation_cache(tmp_path_factory):
    """Command-line runs (here and in subprocesses) keep their compiled programs
    in a folder of the test session, never in the user's cache."""
    os.environ[ENV] = str(tmp_path_factory.mktemp("xla_cache"))
