"""A sweep batch built in one traced call: the structure it derives from a
scene's ``make``, models equal to member-by-member builds for every built-in
scene, rows equal to single runs both ways, and the fall-back for a scene
that cannot be traced or a sweep over a float read as structure."""

from pathlib import Path

import jax
import numpy as np
import pytest

from nsga_jax._batch import stack_models
from nsga_jax._grid import members
from nsga_jax._results import ConfigError
from nsga_jax._scenes.params import positive
from nsga_jax._scenes.spec import SceneSpec
from nsga_jax._sweep import sweep
from nsga_jax._sweep_build import build_batch, structural_floats, traced_structure
from nsga_jax.scenes import REGISTRY, configure, load_scene

ROOT = Path(__file__).resolve().parents[1]


def test_structural_floats_are_read_from_make():
    bar = configure("impacting_bar")
    assert structural_floats(bar.spec, bar.parameters) == ("length",)  # it places the observed node
    ball = configure("bouncing_ball")
    assert structural_floats(ball.spec, ball.parameters) == ("mu", "vx", "spin")  # they choose the planar ball
    assert traced_structure(members("bouncing_ball", {"e": [0.5, 0.9]}, None, None)) == ("mu", "vx", "spin")
    assert traced_structure(members("bouncing_ball", {"mu": [0.0, 0.5]}, None, None)) is None


def test_a_make_that_branches_on_a_float_cannot_be_traced():
    def make(p, concrete):
        if p["k"] > 1.0:  # a Python branch on a swept value: not traceable
            raise AssertionError("never reached with k = 1")
        return None, None, None, None

    spec = SceneSpec(name="branching", description="", parameters={"k": positive(1.0, "k", "")},
                     solver_defaults={}, make=make)
    assert structural_floats(spec, {"k": 1.0}) is None


def _two_values(name: str) -> dict[str, list[float]]:
    """Two valid values of each float parameter that is not structure."""
    config = configure(name)
    structural = structural_floats(config.spec, config.parameters)
    assert structural is not None, name
    grid = {}
    for k, p in config.spec.parameters.items():
        if p.kind != "float" or k in structural:
            continue
        x = float(config.parameters[k])
        other = x * 1.03 if x != 0.0 else 1e-3
        try:
            configure(name, {k: other})
        except ConfigError:
            continue
        grid[k] = [x, other]
        if len(grid) == 2:
            break
    return grid


@pytest.mark.parametrize("name", sorted(REGISTRY))
def test_traced_batch_equals_member_by_member_builds(name):
    grid = _two_values(name)
    mems = members(name, grid, None, None)
    config = mems[0].configured
    built = build_batch(mems, structural_floats(config.spec, config.parameters))
    scenes = [m.scene for m in mems]
    reference = stack_models([s.model for s in scenes])
    assert jax.tree_util.tree_structure(built.model) == jax.tree_util.tree_structure(reference)
    for x, y in zip(jax.tree_util.tree_leaves(built.model), jax.tree_util.tree_leaves(reference)):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(built.q0, np.stack([s.q0 for s in scenes]), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(built.v0, np.stack([s.v0 for s in scenes]), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("grid", [{"E": [900.0, 950.0], "velocity": [10.0, 8.0]}, {"length": [10.0, 6.0]}],
                         ids=["traced", "length swept: member by member"])
def test_bar_sweep_equals_single_runs(grid):
    """The bar's observables (its energy needs the members' matrices) from
    the traced batch, and from member-by-member builds where the swept length
    moves the observed node, equal single runs."""
    settings = {"t_end": 0.02, "n_elements": 20, "gap": 0.01}
    mems = members("impacting_bar", grid, None, settings)
    assert (traced_structure(mems) is None) == ("length" in grid)
    res = sweep("impacting_bar", grid, overrides=settings, batch_size=8)
    for row in res.rows:
        sol = load_scene("impacting_bar", {**settings, **{k: row[k] for k in grid}}).run()
        assert row["n_steps"] == sol.n_steps and row["result"] == "successful"
        for name, y in sol.observables.items():
            assert row[f"{name}_final"] == pytest.approx(y[-1], rel=1e-9, abs=1e-9), name
            assert row[f"{name}_max"] == pytest.approx(y.max(), rel=1e-9, abs=1e-9), name


def test_the_batches_of_one_structure_compile_once():
    """Three batches of one structure add at most the two programs of a batch
    (preparation, chunk) to the compiled programs, not two per batch."""
    from nsga_jax import _batch as batch

    before = len(batch._EXECUTABLES)
    res = sweep("bouncing_ball", {"e": [0.5, 0.7, 0.9]}, overrides={"t_end": 0.05, "height": 0.37}, batch_size=1)
    assert sorted({r["batch"] for r in res.rows}) == [0, 1, 2]
    assert len(batch._EXECUTABLES) - before <= 2


def test_system_file_sweep_is_traced_and_equals_single_runs():
    """A system file's scene (the sliding block with friction) is built
    traced; its rows equal single runs."""
    path = str(ROOT / "nsga_jax" / "configs" / "systems" / "sliding_block.toml")
    grid = {"bodies.block.mass": [1.0, 1.1], "bodies.block.velocity.0": [2.0, 1.5]}
    settings = {"t_end": 0.2}
    assert traced_structure(members(path, grid, None, settings)) == ()
    res = sweep(path, grid, overrides=settings)
    assert len(res.rows) == 4
    for row in res.rows:
        sol = load_scene(path, {**settings, **{k: row[k] for k in grid}}).run()
        assert row["n_steps"] == sol.n_steps and row["result"] == "successful"
        for name, y in sol.observables.items():
            if y.ndim == 1:
                assert row[f"{name}_final"] == pytest.approx(y[-1], rel=1e-9, abs=1e-12), name
