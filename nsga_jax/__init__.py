"""nsga_jax: nonsmooth multibody dynamics with the decoupled nonsmooth generalized-α scheme.

Importing the package is cheap: the numerical modules (and JAX) load when a
name that needs them is first used (``nsga_jax.simulate``, ``nsga_jax.DS``,
...), so that the command line answers ``--help`` and input errors at once.

Importing it changes nothing outside it: no JAX option, no environment
variable. Runs are float64 by default, which needs JAX's 64-bit mode on:
call ``jax.config.update("jax_enable_x64", True)`` once, at the top of the
program, before building models (or set ``JAX_ENABLE_X64=1``), or
``nsga_jax.configure_jax()``, which also sets the XLA CPU flag nsga_jax's
steps run faster with (:mod:`nsga_jax.process_settings`). A float64 run
with the mode off is refused by name (:class:`ConfigError`), never computed
in float32; ``dtype="float32"`` runs either way. The command line
(``nsga-jax``) calls ``configure_jax()`` for its own process.
"""

import importlib

from .results import ConfigError, ConvergenceError, InvariantError  # (no JAX)

__version__ = "0.1.0"

_LAZY = {
    "Solution": ".solution",
    "SaveAt": ".saveat",
    "integrate": "._integrate",
    "simulate": "._simulate",
    "simulate_batch": ".batch",
    "configure_jax": ".process_settings",
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
    "load_scene": ".scenes",
    "Tolerances": ".monitors",
    "check_model": ".models.check",
    "System": ".system",
    "InvariantWarning": "._simulate",
    "RedundantConstraintsWarning": ".models.redundancy",
    "PrecisionWarning": ".precision",
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
    "System",
    "Result",
    "RESULTS",
    "ConfigError",
    "ConvergenceError",
    "InvariantError",
    "InvariantWarning",
    "RedundantConstraintsWarning",
    "PrecisionWarning",
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
