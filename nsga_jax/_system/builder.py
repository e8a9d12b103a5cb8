"""``System``: the builder that assembles named parts into a model.

::

    system = nj.System(dim=2, gravity=[0.0, -9.81])
    system.add_body("link", nj.RigidBody2D(mass=1.0, inertia=0.1, position=[0.5, 0.0]))
    system.add_joint("pivot", nj.Pin("ground", "link", at_b=[-0.5, 0.0]))
    system.add_contact("wall", nj.PlaneContact("link", normal=[-1.0, 0.0], origin=[0.9, 0.0], e=0.5,
                                               points=[[0.5, 0.0]]))
    model, q0, v0 = system.build()

Names are checked when a part is added (identifiers, unique within their
kind, ``ground`` reserved); references, dimensions and anchors when the
model is built, and the initial state against every joint and contact by
:func:`check_initial_state`: each error names the part.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from .._custom_types import Vector
from .._models.redundancy import conflict
from .._results import ConfigError
from .base import GROUND, AbstractBody, AbstractContact, AbstractForce, AbstractJoint
from .forces import Gravity
from .model import SystemModel

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")

KINDS = {"bodies": AbstractBody, "joints": AbstractJoint, "contacts": AbstractContact, "forces": AbstractForce}
"""The four kinds of parts and their base classes (the sections of a system file)."""


class System:
    """A mutable collection of named parts; :meth:`model` assembles them.

    Args:
        dim: space dimension of every body (1, 2 or 3).
        gravity: a uniform acceleration (dim,) [m/s²] on every body, added as
            the force ``gravity`` when the model is built (``None``: none).
    """

    def __init__(self, dim: int, gravity: Any = None):
        if isinstance(dim, bool) or dim not in (1, 2, 3):
            raise ConfigError(f"dim must be 1, 2 or 3 (the space dimension), got {dim!r}")
        self.dim = dim
        self.parts: dict[str, dict[str, Any]] = {kind: {} for kind in KINDS}
        if gravity is not None:
            g = np.asarray(gravity, dtype=float)
            if g.shape != (dim,):
                raise ConfigError(f"gravity must have {dim} coordinates (the system's dim), got {g.tolist()}")
            self.add("forces", "gravity", Gravity(g.tolist()))

    def add(self, kind: str, name: str, part: Any) -> str:
        """Add ``part`` under ``name`` to ``kind`` (``"bodies"``, ``"joints"``,
        ``"contacts"`` or ``"forces"``); returns the name."""
        if kind not in KINDS:
            raise ConfigError(f"unknown kind of part {kind!r}; allowed: {', '.join(KINDS)}")
        if not isinstance(name, str) or not _NAME.match(name):
            raise ConfigError(f"{kind}: a part's name must be an identifier (letters, digits, _), got {name!r}")
        if name == GROUND:
            raise ConfigError(f"{kind}.{name}: 'ground' is the fixed frame's name; choose another")
        if name in self.parts[kind]:
            raise ConfigError(f"{kind}.{name}: the name is used twice")
        if not isinstance(part, KINDS[kind]):
            raise ConfigError(f"{kind}.{name}: expected a {KINDS[kind].__name__}, got {type(part).__name__}")
        self.parts[kind][name] = part
        return name

    def add_body(self, name: str, body: AbstractBody) -> str:
        return self.add("bodies", name, body)

    def add_joint(self, name: str, joint: AbstractJoint) -> str:
        return self.add("joints", name, joint)

    def add_contact(self, name: str, contact: AbstractContact) -> str:
        return self.add("contacts", name, contact)

    def add_force(self, name: str, force: AbstractForce) -> str:
        return self.add("forces", name, force)

    def model(self) -> SystemModel:
        """The assembled model (references and anchors checked)."""
        if not self.parts["bodies"]:
            raise ConfigError("a system needs at least one body")
        everyone = tuple(self.parts["bodies"])
        forces = {name: (Gravity(f.acceleration, on=everyone) if isinstance(f, Gravity) and not f.on else f)
                  for name, f in self.parts["forces"].items()}
        return SystemModel(
            bodies=tuple(self.parts["bodies"].values()), joints=tuple(self.parts["joints"].values()),
            contacts=tuple(self.parts["contacts"].values()), forces=tuple(forces.values()),
            body_names=everyone, joint_names=tuple(self.parts["joints"]),
            contact_names=tuple(self.parts["contacts"]), force_names=tuple(forces), dim=self.dim,
        )

    def build(self, *, tolerance: float = 1e-9) -> tuple[SystemModel, Vector, Vector]:
        """``(model, q0, v0)``: the model and the bodies' initial state, checked
        by :func:`check_initial_state`."""
        model = self.model()
        q0, v0 = model.initial_state()
        check_initial_state(model, q0, v0, tolerance=tolerance)
        return model, q0, v0


def _residuals(model: SystemModel, q0: Vector, v0: Vector) -> tuple[Vector, Vector]:
    """``(g(q0), g_q(q0) v0)``: every constraint at the initial state, and its rate."""
    return model.constraints(q0), model.constraint_jacobian(q0) @ v0


_compiled_residuals: Any = None


def check_initial_state(model: SystemModel, q0: Vector, v0: Vector, *, tolerance: float = 1e-9) -> None:
    """Refuse, by name, an initial state that violates a joint (position or
    velocity level, beyond ``tolerance`` times the state's size) or
    penetrates a contact; joints that no placement can satisfy together (two
    welds of one body at different places) are refused as such
    (:func:`~nsga_jax._models.redundancy.conflict`). The constraints are evaluated by one compiled
    program (compiled once per system structure, so that a sweep's members
    are checked cheaply). Skipped where the state is traced."""
    global _compiled_residuals
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    if any(isinstance(x, jax.core.Tracer) for x in (q0, v0, *jax.tree_util.tree_leaves(model))):
        return
    if _compiled_residuals is None:
        _compiled_residuals = eqx.filter_jit(_residuals)
    q0, v0 = jnp.asarray(q0, float), jnp.asarray(v0, float)
    g, w = (np.asarray(x) for x in _compiled_residuals(model, q0, v0))
    scale = max(1.0, float(np.abs(np.asarray(q0)).max(initial=0.0)))
    vscale = max(1.0, float(np.abs(np.asarray(v0)).max(initial=0.0)))
    start = 0
    for b, name in zip(model.bodies, model.body_names):
        own = g[start:start + b.n_bilateral]
        if own.size and np.abs(own).max() > tolerance * scale:
            raise ConfigError(f"bodies.{name}: the initial orientation is not a rotation (its natural coordinates "
                              f"violate rigidity by {np.abs(own).max():.3g} m)")
        start += b.n_bilateral
    violated = any(np.abs(g[model.rows("joints", name)]).max(initial=0.0) > tolerance * scale
                   for name in model.joint_names)
    contradiction = conflict(model, q0, tolerance * scale) if violated else None
    if contradiction:  # no placement can satisfy the joints: say so rather than "place the bodies"
        raise ConfigError(contradiction)
    for name in model.joint_names:
        rows = model.rows("joints", name)
        if np.abs(g[rows]).max(initial=0.0) > tolerance * scale:
            raise ConfigError(f"joints.{name}: violated at the initial state by {np.abs(g[rows]).max():.3g} m "
                              f"(g = {np.round(g[rows], 12).tolist()}); place the bodies so that it holds")
        if np.abs(w[rows]).max(initial=0.0) > tolerance * vscale:
            raise ConfigError(f"joints.{name}: the initial velocities violate it by {np.abs(w[rows]).max():.3g} m/s "
                              "(their relative motion is not one the joint allows)")
    for name in model.contact_names:
        gaps = g[model.rows("contacts", name)]
        if gaps.size and gaps.min() < -tolerance * scale:
            i = int(np.argmin(gaps))
            raise ConfigError(f"contacts.{name}: initial penetration of {-gaps[i]:.3g} m at point {i} "
                              "(the gap must start >= 0)")
