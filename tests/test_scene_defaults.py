"""Every built-in scene runs at its own defaults: what `nsga-jax run SCENE`
does before a user changes anything."""

import numpy as np
import pytest

from nsga_jax.scenes import REGISTRY, load_scene

BUILT_IN = sorted(name for name, spec in REGISTRY.items() if spec.make.__module__.startswith("nsga_jax.scenes."))


@pytest.mark.parametrize("name", BUILT_IN)
def test_every_scene_runs_at_its_defaults(name):
    scene = load_scene(name)
    sol = scene.run()
    assert sol.stats["result"] == "successful" and sol.stats["failed_steps"] == 0
    assert sol.stats["max_penetration"] <= 1e-7  # the contacts' Newton tolerance (the cube: 1.1e-8 m)
    assert sol.stats["max_bilateral_violation_position"] <= 1e-7
    assert np.isfinite(sol.q).all()



FRICTION = [
    ("rigid_box", {"mu": 0.5, "e": 0.0}),
    ("flexible_cube", {"mu": 0.5, "vx": 0.2}),
    ("bouncing_ball", {"mu": 0.5, "vx": 1.0, "spin": 10.0}),
]
GROWTH = {"rigid_box": 2e-3,  # the box's energy in natural coordinates wavers by 1.5e-3 in flight, frictionless too
          # the sliding cube's energy rises once, in its impact step (step 8244: 8.9e-8 J, 2.6e-5 of its energy,
          # measured at h = 3e-5 s with the position correction's Coulomb law on the bottom nodes)
          "flexible_cube": 5e-5}
# The box keeps e = 0 here: with e = 0.8 and mu = 0.5 its first impact gains energy (2212.6 -> 2480.6 J of kinetic
# energy under Newton's restitution with a sticking contact, |P_T|/P_N = 0.25, solved exactly; DS gives 2482.0 J):
# Kane and Levinson's paradox of Newton's kinematic restitution with Coulomb friction, a property of the law.


@pytest.mark.parametrize("name, overrides", FRICTION,
                         ids=["rigid_box", "flexible_cube", "bouncing_ball"])
def test_scenes_with_friction_run_at_their_defaults(name, overrides):
    """The scenes that had no friction, with mu > 0 (and a horizontal velocity
    or spin where friction needs one to act): every step converges, the
    friction impulses stay within the cone mu P_N and the energy never grows
    (within round-off, or the box's wavering in flight)."""
    scene = load_scene(name, overrides)
    assert scene.model.n_friction > 0
    sol = scene.run()
    assert sol.stats["result"] == "successful" and sol.stats["failed_steps"] == 0
    assert sol.stats["max_penetration"] <= 1e-7
    energy = np.asarray(sol.observables["energy"])
    assert np.diff(energy).max() <= GROWTH.get(name, 1e-9) * np.abs(energy).max()
    d = scene.model.friction_dim
    tangential = np.linalg.norm(np.asarray(sol.records.friction).reshape(len(sol.ts), -1, d), axis=-1)
    normal = np.asarray(sol.impulse)[:, scene.model.n_bilateral:]
    assert np.all(tangential <= overrides["mu"] * normal * (1 + 1e-8) + 1e-12)
    assert np.abs(np.asarray(sol.records.friction)).max() > 0
