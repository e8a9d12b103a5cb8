"""nsga_jax: nonsmooth multibody dynamics with the decoupled nonsmooth generalized-α scheme.

Importing the package turns on float64 (``jax_enable_x64``): the schemes'
Newton tolerances and constraint checks are meant for double precision.

It also turns off XLA's concurrency-optimised CPU scheduler (unless the user
set ``XLA_FLAGS`` otherwise): with jaxlib 0.10 a program that vmaps dense
solves over step sizes deadlocked on its second execution without this flag
(seen with ``nsga_jax.batch``). The flag only takes effect if nsga_jax is
imported before JAX runs its first computation.
"""

import os

_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler"
if _FLAG not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + f" {_FLAG}=false").strip()

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

from . import scenes  # noqa: E402
from ._simulate import Solution, simulate  # noqa: E402
from .integrators.base import AbstractScheme, StepOutput, StepState  # noqa: E402
from .integrators.coefficients import GenAlphaCoefficients  # noqa: E402
from .integrators.cs import CS  # noqa: E402
from .integrators.ds import DS, DSn  # noqa: E402
from .integrators.mj import MJ  # noqa: E402
from .models import BouncingBall, ElasticBar, Model, RigidPendulum  # noqa: E402
from .results import ConfigError, ConvergenceError, Result  # noqa: E402
from .scenes import load_scene  # noqa: E402
from .trajectory import Trajectory, trajectory  # noqa: E402

SCHEMES = {"ds": DS, "dsn": DSn, "cs": CS, "mj": MJ}
"""Scheme classes by their command-line names."""

__version__ = "0.1.0"

__all__ = [
    "AbstractScheme",
    "DS",
    "DSn",
    "CS",
    "MJ",
    "SCHEMES",
    "GenAlphaCoefficients",
    "StepOutput",
    "StepState",
    "Model",
    "BouncingBall",
    "RigidPendulum",
    "ElasticBar",
    "Result",
    "ConfigError",
    "ConvergenceError",
    "Solution",
    "simulate",
    "scenes",
    "load_scene",
    "Trajectory",
    "trajectory",
]
