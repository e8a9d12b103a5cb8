"""Every bad input is refused with an error naming the field and its range,
before anything is traced or compiled."""

import math
import re

import equinox as eqx
import numpy as np
import pytest
from reference_models import BouncingBall, RigidPendulum

import nsga_jax as nj
from nsga_jax._validation import check_model_fields
from nsga_jax.scenes import REGISTRY, load_scene

pytestmark = pytest.mark.usefixtures("no_compilation")  # (tests/conftest.py)


def refused(match, fn, *args, **kwargs):
    with pytest.raises(nj.ConfigError, match=match):
        fn(*args, **kwargs)


@pytest.mark.parametrize(
    "scene, key, value, match",
    [
        ("bouncing_ball", "mass", -1.0, r"mass \[kg\] must be in \(0, inf\)"),
        ("bouncing_ball", "mass", 0.0, r"mass \[kg\] must be in \(0, inf\)"),
        ("rigid_pendulum", "mass", -2.0, r"mass \[kg\] must be in \(0, inf\)"),
        ("rigid_pendulum", "length", 0.0, r"length \[m\] must be in \(0, inf\)"),
        ("impacting_bar", "length", -10.0, r"length \[m\] must be in \(0, inf\)"),
        ("impacting_bar", "E", -900.0, r"E \[Pa\] must be in \(0, inf\)"),
        ("impacting_bar", "rho", 0.0, r"rho \[kg/m\^3\] must be in \(0, inf\)"),
        ("impacting_bar", "n_elements", 0, r"n_elements must be in \[1, 100000\]"),
        ("impacting_bar", "n_elements", 2.5, r"n_elements must be an integer"),
        ("bouncing_ball", "h", -1e-3, r"h \[s\] must be in \(0, inf\)"),
        ("bouncing_ball", "h", 0.0, r"h \[s\] must be in \(0, inf\)"),
        ("bouncing_ball", "t_end", -1.0, r"t_end \[s\] must be in \(0, inf\)"),
        ("bouncing_ball", "rho_inf", 1.5, r"rho_inf must be in \[0, 1\]"),
        ("bouncing_ball", "rho_inf", -0.1, r"rho_inf must be in \[0, 1\]"),
        ("bouncing_ball", "e", 1.2, r"e must be in \[0, 1\]"),
        ("rigid_pendulum", "e", -0.1, r"e must be in \[0, 1\]"),
        ("impacting_bar", "e", 2.0, r"e must be in \[0, 1\]"),
        ("bouncing_ball", "height", -0.1, r"height .* initial penetration"),
        ("impacting_bar", "gap", -1.0, r"gap .* initial penetration"),
        ("bouncing_ball", "velocity", math.nan, r"velocity \[m/s\] must be finite"),
        ("impacting_bar", "E", math.inf, r"E \[Pa\] must be finite"),
        ("bouncing_ball", "tol_r", 0.0, r"tol_r must be in \(0, 1\)"),
        ("bouncing_ball", "max_iter", 0, r"max_iter must be in \[1, 10000\]"),
        ("impacting_bar", "mass_matrix", "diagonal", r"mass_matrix must be one of 'consistent', 'lumped'"),
        ("bouncing_ball", "mass", "heavy", r"mass \[kg\] must be a number"),
    ],
)
def test_scene_field_is_checked(scene, key, value, match):
    refused(match, load_scene, scene, {key: value})


def test_unknown_key_and_scene():
    refused(r"unknown config key 'stiffness'.*allowed keys: e, gravity", load_scene, "bouncing_ball", {"stiffness": 1})
    refused(r"unknown scene 'box'; built-in scenes", load_scene, "box")


def test_step_longer_than_run():
    refused(r"h must be in \(0, t_end\]", load_scene, "bouncing_ball", {"h": 2.0, "t_end": 1.0})


def test_pendulum_starting_on_the_wall():
    refused(r"starts on the wall", load_scene, "rigid_pendulum", {"angle": 0.0, "wall_x": 0.0})


def test_toml_files(tmp_path):
    bad_key = tmp_path / "a.toml"
    bad_key.write_text('scene = "bouncing_ball"\n[parameters]\nmass = 1.0\nspring = 3.0\n')
    refused(r"unknown bouncing_ball parameter key 'spring'", load_scene, bad_key)
    bad_top = tmp_path / "b.toml"
    bad_top.write_text('scene = "bouncing_ball"\n[solvers]\nh = 1.0\n')
    refused(r"unknown top-level key 'solvers'", load_scene, bad_top)
    no_scene = tmp_path / "c.toml"
    no_scene.write_text("[parameters]\nmass = 1.0\n")
    refused(r"missing key 'scene'", load_scene, no_scene)
    refused(r"does not exist", load_scene, tmp_path / "missing.toml")
    bad_value = tmp_path / "d.toml"
    bad_value.write_text('scene = "impacting_bar"\n[solver]\nrho_inf = 3.0\n')
    refused(r"rho_inf must be in \[0, 1\]", load_scene, bad_value)


# ------------------------------------------------------------------ Python API

BALL = BouncingBall(m=1.0, gravity=9.81, e=0.5)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"h": -1e-3}, r"h must be in \(0, inf\)"),
        ({"h": 0.0}, r"h must be in \(0, inf\)"),
        ({"h": math.nan}, r"h must be finite"),
        ({"h": 2.0}, r"h must be in \(0, t1 - t0\]"),
        ({"t1": -1.0}, r"t1 must be finite and greater than t0"),
        ({"q0": [-0.01]}, r"initial penetration: gap 0 is -0.01"),
        ({"q0": [math.nan]}, r"q0 must be finite"),
        ({"v0": [math.inf]}, r"v0 must be finite"),
        ({"q0": [1.0, 2.0]}, r"q0 must have shape \(1,\)"),
        ({"scheme": nj.DS(rho_inf=1.2)}, r"rho_inf must be in \[0, 1\]"),
        ({"scheme": nj.DS(rho_inf=math.nan)}, r"rho_inf must be in \[0, 1\]"),
        ({"scheme": nj.DS(tol_r=-1.0)}, r"tol_r must be in \(0, inf\)"),
        ({"scheme": nj.DS(max_iter=0)}, r"max_iter must be an integer >= 1"),
        ({"scheme": nj.DS(krylov_min_dof=-1)}, r"krylov_min_dof must be an integer >= 0, got -1"),
        ({"scheme": nj.DSn(krylov_min_dof=1.5)}, r"krylov_min_dof must be an integer >= 0, got float 1.5"),
        ({"scheme": nj.DS(reuse_min_dof=None)}, r"reuse_min_dof must be an integer >= 0, got None"),
    ],
)
@pytest.mark.parametrize("driver", ["simulate", "simulate_batch"])
def test_simulate_arguments_are_checked(kwargs, match, driver):
    """simulate and simulate_batch check their inputs with the same function,
    and refuse the same inputs with the same words (a batch's step sizes ``hs``
    one by one, as ``h``)."""
    args = {"model": BALL, "scheme": nj.DS(), "t0": 0.0, "t1": 1.0, "h": 1e-3, "q0": [1.0], "v0": [0.0]}
    args.update(kwargs)
    if driver == "simulate_batch":
        args["hs"] = [1e-3, args.pop("h")]
    refused(match, getattr(nj, driver), **args)


def test_bilateral_violation_at_start_is_refused():
    pendulum = RigidPendulum(m=1.0, length=1.0, gravity=9.81, wall_x=-0.5, side=1.0, e=0.5)
    refused(r"violates bilateral constraint 0", nj.simulate, pendulum, nj.DS(), 0.0, 1.0, 1e-3,
            np.array([0.0, -1.2]), np.zeros(2))


# ------------------------------------------------- every rule of every field

def _violations(p):
    """(bad value, expected message) for every rule a config field states."""
    rng = re.escape(p.range_text())
    if p.kind == "choice":
        return [("no-such-choice", "must be one of")]
    out = [("abc", "must be a number"), (True, "must be a number"), (math.inf, "must be finite")]
    if p.kind == "float":
        out.append((math.nan, "must be finite"))
    if p.lo > -math.inf:
        out.append((p.lo if p.lo_open else p.lo - max(1.0, abs(p.lo)), f"must be in {rng}"))
    if p.hi < math.inf:
        out.append((p.hi if p.hi_open else p.hi + max(1.0, abs(p.hi)), f"must be in {rng}"))
    if p.kind == "int":
        out.append((p.lo + 0.5, "must be an integer"))
    return out


RULES = [
    pytest.param(scene, key, value, message, id=f"{scene}-{key}-{value!r}")
    for scene, spec in sorted(REGISTRY.items())
    for key, p in {**spec.parameters, **spec.solver_specs()}.items()
    for value, message in _violations(p)
]


@pytest.mark.parametrize("scene, key, value, message", RULES)
def test_every_rule_of_every_config_field(scene, key, value, message):
    with pytest.raises(nj.ConfigError) as info:
        load_scene(scene, {key: value})
    assert re.search(rf"\b{re.escape(key)}\b", str(info.value)), str(info.value)
    assert re.search(message, str(info.value)), str(info.value)


@pytest.mark.parametrize(
    "make, match",
    [
        (lambda: BouncingBall(m=0.0, gravity=9.81, e=0.5), r"BouncingBall.m must be in \(0, inf\), got 0.0"),
        (lambda: BouncingBall(m=1.0, gravity=math.nan, e=0.5), r"BouncingBall.gravity must be finite"),
        (lambda: BouncingBall(m=1.0, gravity=9.81, e=1.5), r"BouncingBall.e must be in \[0, 1\]"),
        (lambda: RigidPendulum(m=1.0, length=-1.0, gravity=9.81, wall_x=-0.5, side=1.0, e=0.5),
         r"RigidPendulum.length must be in \(0, inf\)"),
    ],
)
def test_model_fields_are_checked(make, match):
    """The model's constructor refuses the value (before simulate is reached)."""
    refused(match, make)


def test_model_fields_of_every_scene_are_checked():
    """Every model's declared ranges (a system's: its parts') hold its scene's
    defaults, and each is enforced."""
    from nsga_jax.system import SystemModel

    for name in REGISTRY:
        scene = load_scene(name)
        model = scene.model
        check_model_fields(model)
        modules = ([*model.bodies, *model.joints, *model.contacts, *model.forces] if isinstance(model, SystemModel)
                   else [model])
        assert any(m.ranges for m in modules), f"{name}: no {type(model).__name__} part declares ranges"
        for module in modules:
            check_model_fields(module)
            for field, rng in module.ranges.items():
                if getattr(module, field) is None:  # an optional field left out (a frictionless contact's mu)
                    continue
                bad = rng.lo - 1.0 if rng.lo > -math.inf else rng.hi + 1.0
                value = np.full_like(np.asarray(getattr(module, field)), bad)
                broken = eqx.tree_at(lambda m, f=field: getattr(m, f), module, value)
                with pytest.raises(nj.ConfigError, match=rf"{type(module).__name__}.{field} must be in"):
                    check_model_fields(broken)


def test_rigid_body_inertia_must_be_positive_definite():
    box = load_scene("rigid_box").model.body("box")
    broken = eqx.tree_at(lambda m: m.inertia, box, np.diag([1.0, -1.0, 1.0]))
    refused(r"inertia must be positive definite", check_model_fields, broken)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"dtype": "float16"}, r"dtype must be one of 'float64', 'float32'"),
        ({"record_every": 0}, r"record_every must be an integer >= 1"),
        ({"record_every": 2.5}, r"record_every must be an integer >= 1"),
        ({"chunk_size": -3}, r"chunk_size must be an integer >= 1"),
    ],
)
def test_simulate_options_are_checked(kwargs, match):
    def run():
        options = dict(kwargs)
        if "record_every" in options:  # kept rows: SaveAt(every=k)
            options["saveat"] = nj.SaveAt(every=options.pop("record_every"))
        return nj.simulate(BALL, nj.DS(), 0.0, 1.0, 1e-3, [1.0], [0.0], **options)

    refused(match, run)


def test_integrate_arguments_are_checked():
    refused(r"n_steps must be an integer >= 1", nj.integrate, BALL, nj.DS(), 0.0, 1.0, 1e-3, np.ones(1), np.zeros(1),
            n_steps=0)
    refused(r"q0 must have shape \(1,\)", nj.integrate, BALL, nj.DS(), 0.0, 0.01, 1e-3, np.ones(2), np.zeros(1))
    refused(r"BouncingBall.e must be in", lambda: nj.integrate(BouncingBall(m=1.0, gravity=9.81, e=2.0), nj.DS(),
                                                                 0.0, 0.01, 1e-3, np.ones(1), np.zeros(1)))
