"""nsga_jax: nonsmooth multibody dynamics with the decoupled nonsmooth generalized-α scheme.

Importing the package is cheap: the numerical modules (and JAX) load when a
name that needs them is first used (``nsga_jax.simulate``, ``nsga_jax.DS``,
...), so that the command line answers ``--help`` and input errors at once.

Importing it changes nothing outside it: no JAX option, no environment
variable. Runs are float64 by default, which needs JAX's 64-bit mode on:
call ``jax.config.update("jax_enable_x64", True)`` once, at the top of the
program, before building models (or set ``JAX_ENABLE_X64=1``), or
``nsga_jax.configure_jax()``, which also sets the XLA CPU flag nsga_jax's
steps run faster with (:mod:`nsga_jax._process_settings`). A float64 run
with the mode off is refused by name (:class:`ConfigError`), never computed
in float32; ``dtype="float32"`` runs either way. The command line
(``nsga-jax``) calls ``configure_jax()`` for its own process.
"""

import importlib

from ._results import ConfigError, ConvergenceError, InvariantError  # (no JAX)

__version__ = "0.1.0"

_LAZY = {
    "Solution": "._solution",
    "SaveAt": "._saveat",
    "integrate": "._integrate",
    "simulate": "._simulate",
    "simulate_batch": "._batch",
    "configure_jax": "._process_settings",
    "AbstractScheme": "._integrators.base",
    "StepOutput": "._integrators.records",
    "Result": "._results",
    "RESULTS": "._results",
    "StepState": "._integrators.base",
    "GenAlphaCoefficients": "._integrators.coefficients",
    "CS": "._integrators.cs",
    "DS": "._integrators.ds",
    "DSn": "._integrators.ds",
    "MJ": "._integrators.mj",
    "Model": "._models",
    "load_scene": "._scenes",
    "Tolerances": "._monitors",
    "check_model": "._models.check",
    "System": "._system",
    "InvariantWarning": "._simulate",
    "RedundantConstraintsWarning": "._models.redundancy",
    "PrecisionWarning": "._precision",
    "bilateral_redundancy": "._models.redundancy",
    "AbstractAdjoint": "._adjoint",
    "DiscreteAdjoint": "._adjoint",
    "ImpactTimeAdjoint": "._adjoint",
    "sweep": "._sweep",
    "BatchRun": "._batch",
    "study": "._studies",
    "run_step_sizes": "._studies",
    "make_reference": "._studies",
    "identify": "._identify",
    "synthetic_data": "._identify",
    "Data": "._data",
    "estimate_run_bytes": "._memory",
    "load_chunks": "._chunks",
    "chunk_files": "._chunks",
    "cast_floats": "._precision",
    "use_compilation_cache": "._compilation_cache",
    "initialize_distributed": "._distributed:initialize",
    "write_animation": "._animate",
    "ElementGroup": "._assembly",
    "ElementBlocks": "._models.capabilities",
    "EnergyMonitor": "._models.capabilities",
    "FrictionalContacts": "._models.capabilities",
    "member_mesh": "._batch",
}
_MODULES = ("scenes", "system")


def __getattr__(name: str):
    if name in _LAZY:
        module, _, attribute = _LAZY[name].partition(":")  # "module:attribute" where the names differ
        value = getattr(importlib.import_module(module, __name__), attribute or name)
    elif name in _MODULES:
        value = importlib.import_module(f".{name}", __name__)
    elif name == "SCHEMES":
        from ._integrators import scheme_class
        from ._validation import SCHEME_NAMES

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
    "sweep",
    "system",
    "BatchRun",
    "study",
    "run_step_sizes",
    "make_reference",
    "identify",
    "synthetic_data",
    "Data",
    "estimate_run_bytes",
    "load_chunks",
    "chunk_files",
    "cast_floats",
    "use_compilation_cache",
    "initialize_distributed",
    "write_animation",
    "ElementGroup",
    "ElementBlocks",
    "EnergyMonitor",
    "FrictionalContacts",
    "member_mesh",
]
