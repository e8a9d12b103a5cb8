"""Parameter identification: fit scene parameters to measured motion by gradient
descent through simulations with impacts (optax).

The loss is the mean squared mismatch between the scene's observables and the
data, each observable normalised by the mean square of its data; it is
differentiated through the whole trajectory (:func:`~nsga_jax.integrate`).
The optimiser works on the parameters divided by their starting values (all
of order one) and keeps them inside their allowed ranges.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from ._adjoint import ADJOINT_KINDS, AbstractAdjoint, DiscreteAdjoint
from ._data import Data
from ._first_step import LIMIT_SECONDS, check_limit
from ._fit_steps import (
    MAX_STEP,
    at_bounds,
    bounded_step,
    compass_search,
    flat_bound,
    free_step,
    line_search,
    projected_gradient,
    scaled_bounds,
    to_values,
)
from ._integrate import integrate
from ._results import ConfigError
from ._scenes import load_scene, make_scheme, parametrize
from ._validation import integer, require_instance

OPTIMIZERS = ("lbfgs", "adam")


@dataclass
class Identification:
    """What :func:`identify` found, and how."""

    names: list[str]
    initial: dict[str, float]
    recovered: dict[str, float]
    true: dict[str, float] | None
    losses: list[float]
    iterations: int
    evaluations: int
    stop: str
    wall_time_s: float
    compile_time_s: float
    fitted: dict[str, np.ndarray] = field(default_factory=dict)
    initial_fit: dict[str, np.ndarray] = field(default_factory=dict)
    gradient_norm: float = math.nan
    at_bounds: list[str] = field(default_factory=list)
    noise_floor: float = 0.0
    compass_steps: int = 0

    STOPS = {
        "gradient": "the projected gradient fell below gtol",
        "loss": "an iteration lowered the loss by less than ftol of its value",
        "max_steps": "the iteration cap (max_steps) was reached",
        "minimum": "no step along the search direction lowered the loss, at a local minimum of the simulated loss: "
                   "moving any parameter by 1e-6 of its start raises it (through impacts the loss is piecewise "
                   "smooth on the step grid, and its jumps end line searches)",
        "flat": "no step lowered the loss, where moving some parameter by 1e-6 of its start leaves it unchanged: "
                "the loss is flat here, which is no fit (does an impact that the data show depend on it?)",
        "noise": "the loss reached the data's noise floor (estimated from the data alone): no fit can come "
                 "closer to data with this noise",
        "bound": "it stopped on a bound of the parameters' range where the gradient is zero: the loss is flat "
                 "there, which is no fit (start closer to the data, or fit fewer parameters)",
    }

    @property
    def converged(self) -> bool:
        """Whether the fit ended at a stationary point of the loss inside the
        parameters' ranges (or against a bound the gradient pushes into)."""
        return self.stop in CONVERGED_STOPS

    @property
    def stop_message(self) -> str:
        where = f" ({', '.join(self.at_bounds)} at a bound)" if self.at_bounds else ""
        return f"stopped because {self.STOPS.get(self.stop, self.stop)}{where}"

    def summary(self) -> dict[str, Any]:
        out = {"parameters": self.names, "initial": self.initial, "recovered": self.recovered,
               "iterations": self.iterations, "evaluations": self.evaluations,
               "stopped_by": self.stop, "converged": self.converged, "stop_message": self.stop_message,
               "at_bounds": self.at_bounds, "initial_loss": self.losses[0], "final_loss": self.losses[-1],
               "gradient_norm": self.gradient_norm, "noise_floor": self.noise_floor,
               "compass_steps": self.compass_steps,
               "wall_time_s": self.wall_time_s,
               "compile_time_s": self.compile_time_s}
        if self.true is not None:
            out["true"] = self.true
            out["relative_error"] = {k: abs(self.recovered[k] / self.true[k] - 1.0) if self.true[k] else
                                     abs(self.recovered[k]) for k in self.names}
        return out


CONVERGED_STOPS = ("gradient", "loss", "minimum", "noise")
"""The stops of a fit that fits: a stationary point of the loss, a local
minimum of the simulated loss where the line search ends, or the data's noise floor."""

NOISE_MARGIN = 1.5
"""A fit whose loss is below this multiple of the data's noise floor fits the
data to its noise (the mean square of n noisy samples scatters by sqrt(2/n)
about σ², and the estimate of σ by a few per cent)."""

def _run(build, scheme, h, n_steps, p, adjoint, first_step_limit=LIMIT_SECONDS):
    model, q0, v0, observables = build(p)
    return observables(integrate(model, scheme, 0.0, n_steps * h, h, q0, v0, n_steps=n_steps, adjoint=adjoint,
                                 first_step_limit=first_step_limit))


def synthetic_data(scene_name: str, overrides: dict | None, observables, noise: float = 0.0,
                   seed: int = 0, every: int = 1) -> Data:
    """Data from the scene's own model (its scheme and step), every ``every``-th
    step, with Gaussian noise of standard deviation ``noise`` times each
    observable's RMS."""
    scene = load_scene(scene_name, overrides)
    sol = scene.run()
    rng = np.random.default_rng(seed)
    values = {}
    for k in observables:
        y = np.asarray(sol.observables[k])[::every]
        values[k] = y + noise * np.sqrt(np.mean(y**2)) * rng.normal(size=y.shape)
    return Data(t=sol.ts[::every], values=values)


def identify(
    scene_name: str,
    names: list[str],
    data: Data,
    overrides: dict | None = None,
    initial: dict[str, float] | None = None,
    optimizer: str = "lbfgs",
    max_steps: int = 100,
    learning_rate: float = 0.05,
    gtol: float = 1e-9,
    ftol: float = 1e-10,
    true: dict[str, float] | None = None,
    progress: bool = False,
    adjoint: AbstractAdjoint = DiscreteAdjoint(),
    first_step_limit: float | None = LIMIT_SECONDS,
) -> Identification:
    """Fit the parameters ``names`` of a scene to ``data``.

    Args:
        scene_name: built-in scene or TOML config; ``overrides`` set the other
            parameters and the solver (scheme, h); the run covers the data's times.
        names: float parameters to identify.
        data: measured observables (names of the scene's observables).
        initial: starting values (default: the scene's values).
        optimizer: ``"lbfgs"`` (optax's L-BFGS direction with a backtracking
            Armijo line search) or ``"adam"`` (optax Adam, ``learning_rate`` in
            scaled variables).
        max_steps, gtol, ftol: stop after max_steps iterations, when the
            gradient norm (in scaled variables) falls below gtol, or when an
            iteration lowers the loss by less than ftol times its value.
        true: the true values, when known (synthetic data), for the report.
        progress: print the loss and the parameters after each iteration (stderr).
        adjoint: :class:`~nsga_jax.DiscreteAdjoint` (default: the derivative of
            the simulated loss itself, which its line searches descend) or
            :class:`~nsga_jax.ImpactTimeAdjoint` (gradients that see impact
            instants move, :mod:`nsga_jax._impact_time`); see
            :mod:`nsga_jax._adjoint`. The default is measured: on data the
            fitted model did not make, both reach the same fits, the discrete
            one in 1.4 to 51 times fewer loss evaluations
            (``experiments/studies/identify_exact_data.py``, docs/gradients.md).
        first_step_limit: refuse, before compiling, a model whose first step
            is estimated above this many seconds (``integrate``'s; ``None``:
            no limit).

    One function is compiled: the loss, its gradient (through the whole
    trajectory) and the predicted observables, together; every evaluation,
    line-search trials included, reuses it.
    """
    if optimizer not in OPTIMIZERS:
        raise ConfigError(f"optimizer must be one of {', '.join(OPTIMIZERS)}, got {optimizer!r}")
    integer("max_steps", max_steps, 1)
    check_limit("first_step_limit", first_step_limit)
    require_instance("adjoint", adjoint, AbstractAdjoint, ADJOINT_KINDS)
    data.check()
    overrides = dict(overrides or {})
    start = {**overrides, **(initial or {})}
    scene = load_scene(scene_name, start)
    unknown = [k for k in data.values if k not in scene.spec.observables]
    if unknown:
        raise ConfigError(f"data has unknown observable {unknown[0]!r}; {scene.name} has "
                          f"{', '.join(scene.spec.observables)}")
    h = scene.solver["h"]
    n_steps = max(1, int(math.ceil(float(np.max(data.t)) / h - 1e-9)))
    params0, build = parametrize(scene_name, start, names)
    specs = scene.spec.parameters
    # Scaled variables u = p / scale, of order one.
    scale = {k: float(params0[k]) if float(params0[k]) != 0.0 else 1.0 for k in names}
    bounds = {k: scaled_bounds(specs[k], scale[k]) for k in names}
    scheme = make_scheme(scene.solver)
    t_data = jnp.asarray(data.t)
    ts = jnp.arange(n_steps + 1) * h
    targets = {k: jnp.asarray(v) for k, v in data.values.items()}
    weights = {k: 1.0 / max(float(np.mean(v**2)), 1e-300) for k, v in data.values.items()}
    noise = data.noise_std()
    noise_floor = sum(weights[k] * noise[k] ** 2 for k in targets)

    def loss_and_prediction(u):
        obs = _run(build, scheme, h, n_steps, {k: u[k] * scale[k] for k in names}, adjoint, first_step_limit)
        pred = {k: jnp.interp(t_data, ts, obs[k]) for k in targets}
        loss = sum(weights[k] * jnp.mean((pred[k] - targets[k]) ** 2) for k in targets)
        return loss, pred

    def advance(u, step, alpha):
        """``u + alpha * step``, projected on the parameters' ranges."""
        return {k: jnp.clip(u[k] + alpha * step[k], *bounds[k]) for k in names}

    u0 = {k: jnp.asarray(float(params0[k]) / scale[k]) for k in names}
    tc = time.perf_counter()
    evaluate = jax.jit(jax.value_and_grad(loss_and_prediction, has_aux=True)).lower(u0).compile()
    opt = optax.lbfgs(linesearch=None) if optimizer == "lbfgs" else optax.adam(learning_rate)
    state = opt.init(u0)
    direction = jax.jit(opt.update).lower(u0, state, u0).compile()
    advance = jax.jit(advance).lower(u0, u0, 1.0).compile()
    compile_time = time.perf_counter() - tc

    t0 = time.perf_counter()
    u = u0
    (value, pred), grad = evaluate(u)
    initial_fit = pred
    losses, evaluations, stop, compass_steps = [float(value)], 1, "max_steps", 0
    it = 0
    while it < max_steps:
        if not math.isfinite(losses[-1]):
            raise ConfigError(f"the loss is not finite at {to_values(u, scale)}; start closer to the data")
        active = at_bounds(u, bounds)
        if float(optax.tree.norm(projected_gradient(grad, active))) < gtol:
            stop = "bound" if flat_bound(active, grad, losses, gtol) else "gradient"
            break
        it += 1
        step, state = direction(grad, state, u)
        step = bounded_step(free_step(step, active), MAX_STEP)
        if optimizer == "adam":
            u = advance(u, step, 1.0)
            (value, pred), grad = evaluate(u)
            evaluations += 1
        else:
            accepted, n = line_search(evaluate, advance, u, losses[-1], projected_gradient(grad, active), step)
            if accepted is None:  # restart L-BFGS from the (normalised) gradient direction
                state = jax.tree.map(jnp.asarray, opt.init(u))
                step, state = direction(grad, state, u)
                step = bounded_step(free_step(step, active), MAX_STEP)
                accepted, m = line_search(evaluate, advance, u, losses[-1], projected_gradient(grad, active), step)
                n += m
            evaluations += n
            if accepted is None:
                accepted, m, flat = compass_search(evaluate, advance, u, losses[-1], names)
                evaluations += m
                if accepted is None:
                    stop = "flat" if flat else "minimum"
                    break
                compass_steps += 1
                state = jax.tree.map(jnp.asarray, opt.init(accepted[0]))
            u, value, pred, grad = accepted
        losses.append(float(value))
        stalled = optimizer == "lbfgs" and losses[-2] - losses[-1] <= ftol * abs(losses[-2])
        if progress:
            values = ", ".join(f"{k} = {v:.6g}" for k, v in to_values(u, scale).items())
            print(f"  iteration {it}: loss {losses[-1]:.6e}, {values} ({evaluations} evaluations)",
                  file=sys.stderr, flush=True)
        if stalled:
            active = at_bounds(u, bounds)
            stop = "bound" if flat_bound(active, grad, losses, gtol) else "loss"
            break
    if stop in ("flat", "max_steps") and losses[-1] <= NOISE_MARGIN * noise_floor:
        stop = "noise"
    wall = time.perf_counter() - t0
    return Identification(
        names=list(names), initial=to_values(u0, scale), recovered=to_values(u, scale),
        true=None if true is None else {k: float(true[k]) for k in names}, losses=losses, iterations=it,
        evaluations=evaluations, stop=stop, wall_time_s=wall, compile_time_s=compile_time,
        fitted={k: np.asarray(v) for k, v in pred.items()},
        initial_fit={k: np.asarray(v) for k, v in initial_fit.items()},
        gradient_norm=float(optax.tree.norm(grad)), at_bounds=sorted(at_bounds(u, bounds)),
        noise_floor=noise_floor, compass_steps=compass_steps,
    )


def write_identification(result: Identification, data: Data, out_dir, title: str = "", *,
                         scene=None, plots: bool = True) -> dict[str, Path]:
    """Write ``identification.json`` and, with ``plots``, ``loss.png`` (loss per iteration) and
    ``fit.png`` (data, initial and fitted observables against t [s]); returns
    the paths.

    ``scene`` (the :class:`~nsga_jax.scenes.Scene` that was fitted, or a
    scene name) gives the observables' units and the figures' titles (scene,
    scheme, h); ``title`` replaces the default second line of the titles
    (``identification of ...``)."""
    from . import _plotting as plotting

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"json": out / "identification.json", "loss": out / "loss.png", "fit": out / "fit.png"}
    paths["json"].write_text(json.dumps(result.summary(), indent=2) + "\n")
    if not plots:
        return {"json": paths["json"]}
    solver = getattr(scene, "solver", None) or {}
    spec = plotting.scene_spec(scene)
    found = ", ".join(f"{k}: {result.initial[k]:.4g} → {result.recovered[k]:.4g}"
                      + (f" (true {result.true[k]:.4g})" if result.true else "") for k in result.names)
    what = title or f"identification of {found}"
    heading = plotting.title(spec.name if spec is not None else "", solver.get("scheme", ""),
                             solver["h"] if "h" in solver else (), what)

    with plotting.style():
        fig, axes = plotting.figure(1, 1, panel=(5.6, 3.4))
        ax = axes[0, 0]
        ax.semilogy(np.arange(len(result.losses)), np.maximum(result.losses, 1e-300), "o-", ms=3)
        ax.set_xlabel("iteration")
        ax.set_ylabel(plotting.label("loss (normalised mean square)", ""))
        plotting.integer_ticks(ax, "x", top=len(result.losses) - 1)
        plotting.log_ticks(ax, "y")
        fig.suptitle(f"{heading}\n{result.iterations} iterations, {result.evaluations} evaluations, "
                     f"stopped by {result.stop}")
    paths["loss"] = plotting.save(fig, paths["loss"])

    names = list(data.values)
    with plotting.style():
        fig, axes = plotting.figure(len(names), 1, panel=(7.0, 2.3), sharex=True)
        for ax, k in zip(axes[:, 0], names):
            ax.plot(data.t, data.values[k], ".", ms=3, color="0.5", label="data")
            ax.plot(data.t, result.initial_fit[k], "--", lw=1, label="initial")
            ax.plot(data.t, result.fitted[k], "-", lw=1.2, label="fitted")
            ax.set_ylabel(plotting.label(k, plotting.observable_unit(spec, k)))
            plotting.plain_ticks(ax, "x")
        axes[0, 0].legend(loc="best")
        axes[-1, 0].set_xlabel("t [s]")
        fig.suptitle(heading)
    paths["fit"] = plotting.save(fig, paths["fit"])
    return paths
