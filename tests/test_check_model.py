"""``check_model``: every built-in model's declared structure holds, and a
wrong structure flag is caught with a message naming the flag."""

import jax.numpy as jnp
import pytest
from reference_models import ElasticBar, RigidPendulum

import nsga_jax as nj
from nsga_jax.scenes import REGISTRY, load_scene


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_built_in_models_keep_their_declarations(name):
    scene = load_scene(name, {"n_elements": 4} if name in ("flexible_pendulum", "impacting_bar") else
                       {"divisions": 2} if name == "flexible_cube" else {})
    checked = nj.check_model(scene.model, scene.q0, scene.v0)
    assert {"sizes", "mass_product", "tangents"} <= set(checked)
    assert ("constant_mass" in checked) == scene.model.constant_mass
    assert ("energy" in checked) == scene.model.has_energy


def test_the_worked_example_model_keeps_its_declarations():
    """The user model of docs/own-model.md (the double pendulum) as well."""
    from pathlib import Path

    scene = load_scene(Path(__file__).resolve().parents[1] / "nsga_jax/examples/double_pendulum.py")
    checked = nj.check_model(scene.model, scene.q0, scene.v0)
    assert {"sizes", "mass_product", "tangents", "constant_mass"} <= set(checked)


PENDULUM = dict(m=1.0, length=1.0, gravity=9.81, wall_x=-0.5, side=1.0, e=0.5)


class MassGrowsWithHeight(RigidPendulum):
    def mass(self, q):
        return self.m * (1.0 + q[1] ** 2) * jnp.eye(2, dtype=q.dtype)

    def mass_product(self, q, x):
        return self.mass(q) @ x


class CubicSpring(RigidPendulum):
    def force(self, q, v, t):
        return -self.m * q**3


class Damped(RigidPendulum):
    def force(self, q, v, t):
        return -0.1 * v


class AffineRod(RigidPendulum):
    linear_constraints = True


class HalfKinetic(RigidPendulum):
    def energy(self, q, v):
        return 0.25 * self.m * (v @ v) + self.m * self.gravity * q[1]


class PotentialUpsideDown(RigidPendulum):
    def energy(self, q, v):
        return 0.5 * self.m * (v @ v) - self.m * self.gravity * q[1]


class Diagonal(ElasticBar):
    @property
    def bandwidth(self):
        return 0


@pytest.mark.parametrize("model, flag", [
    (MassGrowsWithHeight(**PENDULUM), r"constant_mass: declared True, but M\(q\) changes with q"),
    (CubicSpring(**PENDULUM), r"linear_force: declared True, but the tangents K, C change"),
    (Damped(**PENDULUM), r"velocity_dependent_force: declared False, but the force depends on v"),
    (AffineRod(**PENDULUM), r"linear_constraints: declared True, but the constraint Jacobian g_q changes"),
    (Diagonal(E=900.0, rho=1.0, area=1.0, length=10.0, gap0=1.0, e=0.0, n_elements=8),
     r"bandwidth: declared 0, but M has entries .* outside that band"),
    (HalfKinetic(**PENDULUM), r"energy: dE/dv differs from M\(q\) v by 5.00e-01 .*not 1/2 v\^T M v"),
    (PotentialUpsideDown(**PENDULUM), r"energy: dE/dq differs from -f\(q\) by 2.00e\+00 .*not the force's"),
])
def test_a_wrong_flag_is_named(model, flag):
    with pytest.raises(nj.ConfigError, match=flag):
        nj.check_model(model, jnp.ones(model.n_dof) * 0.3)
