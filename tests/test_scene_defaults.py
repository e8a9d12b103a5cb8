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
