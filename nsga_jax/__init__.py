"""nsga_jax: nonsmooth multibody dynamics with the decoupled nonsmooth generalized-α scheme.

Importing the package is cheap: the numerical modules (and JAX) load when a
name that needs them is first used (``nsga_jax.simulate``, ``nsga_jax.DS``,
...), so that the command line answers ``--help`` and input errors at once.

Side effects, both documented in docs/python-api.md:

- **float64.** When the numerical modules load, they turn on JAX's
  ``jax_enable_x64``: the schemes' Newton tolerances and constraint checks are
  meant for double precision. Set the environment variable
  ``NSGA_JAX_X64=0`` before the first use to leave JAX's setting alone (runs
  then need ``dtype="float32"``, or x64 enabled by the caller).
- **XLA flags.** ``import nsga_jax`` adds
  ``--xla_cpu_enable_concurrency_optimized_scheduler=false`` to ``XLA_FLAGS``
  (unless the user set that flag): with jaxlib 0.10 a program that vmaps
  dense solves over step sizes deadlocked on its second execution without
  it. It only takes effect if nsga_jax is imported before JAX runs its first
  computation; set the flag yourself in ``XLA_FLAGS`` to choose otherwise.
"""

import importlib
import os

_FLAG = "--xla_cpu_enable_concurrency_optimized_scheduler"
if _FLAG not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + f" {_FLAG}=false").strip()

from .results import ConfigError, ConvergenceError, InvariantError  # noqa: E402  (no JAX)

__version__ = "0.1.0"

_LAZY = {
    "Solution": ".solution",
    "SaveAt": ".saveat",
    "integrate": "._integrate",
    "simulate": "._simulate",
    "simulate_batch": ".batch",
    "AbstractScheme": ".integrators.base",
    "StepOutput": ".integrators.records",
    "Result": ".results",
    "RESULTS": ".results",
    "StepState": ".integrators.base",
    "GenAlphaCoefficients": ".integrators.coefficients",
    "CS": ".integrators.cs",
    "DS": ".integrators.ds",
    "DSn": ".integrators.ds",
    "MJ": ".integrators.mj",
    "Model": ".models",
    "BouncingBall": ".models",
    "RigidPendulum": ".models",
    "ElasticBar": ".models",
    "load_scene": ".scenes",
    "Tolerances": ".monitors",
    "check_model": ".models.check",
    "System": ".system",
    "InvariantWarning": "._simulate",
    "RedundantConstraintsWarning": ".models.redundancy",
    "bilateral_redundancy": ".models.redundancy",
    "AbstractAdjoint": ".adjoint",
    "DiscreteAdjoint": ".adjoint",
    "ImpactTimeAdjoint": ".adjoint",
}
_MODULES = ("scenes", "system")


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    elif name in _MODULES:
        value = importlib.import_module(f".{name}", __name__)
    elif name == "SCHEMES":
        from .integrators import scheme_class
        from .validation import SCHEME_NAMES

        value = {name: scheme_class(name) for name in SCHEME_NAMES}
    else:
        raise AttributeError(f"module 'nsga_jax' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(list(globals()) + list(_LAZY) + list(_MODULES) + ["SCHEMES"])


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
    "System",
    "Result",
    "RESULTS",
    "ConfigError",
    "ConvergenceError",
    "InvariantError",
    "InvariantWarning",
    "RedundantConstraintsWarning",
    "bilateral_redundancy",
    "Solution",
    "SaveAt",
    "integrate",
    "simulate",
    "simulate_batch",
    "scenes",
    "load_scene",
    "Tolerances",
    "check_model",
    "AbstractAdjoint",
    "DiscreteAdjoint",
    "ImpactTimeAdjoint",
]
