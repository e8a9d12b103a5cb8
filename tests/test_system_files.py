"""System files: a TOML scene of catalogued parts, every number a parameter
with a dotted path; validation by name before anything compiles; the
examples in configs/systems/ run, sweep and differentiate."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

from nsga_jax._cli import EXIT_INPUT, main
from nsga_jax._results import ConfigError
from nsga_jax._system.catalog import CATALOG, fields
from nsga_jax.scenes import REGISTRY, configure, load_scene, parametrize
from nsga_jax.system import PlaneContact, PointMass, RigidBody2D, System, TorsionalSpring

SYSTEMS = Path(__file__).resolve().parents[1] / "nsga_jax" / "configs" / "systems"
BALL = SYSTEMS / "ball_between_walls.toml"
PENDULUM = SYSTEMS / "double_pendulum_wall.toml"
CHAIN = SYSTEMS / "spring_chain.toml"


pytestmark = pytest.mark.usefixtures("scene_registry")  # system files register scenes (conftest)


def _variant(tmp_path: Path, source: Path, old: str, new: str, name: str | None = None) -> Path:
    text = source.read_text()
    assert old in text, old
    path = tmp_path / (name or source.name)
    path.write_text(text.replace(old, new, 1))
    return path


# ------------------------------------------------------------------ catalog


def test_catalog_fields_come_from_the_constructors():
    mass = fields(PointMass)
    assert list(mass) == ["mass", "position", "velocity"]
    assert mass["mass"].kind == "float" and mass["mass"].required and mass["mass"].unit == "kg"
    assert mass["mass"].range.lo == 0.0 and mass["mass"].range.lo_open  # PointMass.ranges["mass_"]
    assert not mass["velocity"].required and mass["velocity"].default is None
    rigid = fields(RigidBody2D)
    assert rigid["velocity"].default == (0.0, 0.0) and rigid["inertia"].unit == "kg m^2"
    plane = fields(PlaneContact)
    assert plane["body"].kind == "str" and plane["nodes"].kind == "nodes" and plane["e"].range.hi == 1.0
    assert fields(TorsionalSpring)["stiffness"].unit == "N m/rad"  # a class's own unit
    beam = fields(CATALOG["bodies"]["beam_2d"])
    assert beam["n_elements"].kind == "int" and beam["lumped"].kind == "bool" and beam["E"].unit == "Pa"
    assert "function" not in fields(CATALOG["forces"]["prescribed"])  # Python only
    for kind, types in CATALOG.items():
        for type_name, cls in types.items():
            assert fields(cls), (kind, type_name)


# ------------------------------------------------------------ scene and paths


def test_a_system_file_is_a_scene_with_dotted_parameters():
    configured = configure(str(BALL))
    spec = configured.spec
    assert spec.name == "ball_between_walls" and REGISTRY[spec.name] is spec
    p = spec.parameters
    assert p["bodies.ball.mass"].default == 0.5 and p["bodies.ball.mass"].unit == "kg"
    assert p["bodies.ball.velocity.0"].default == 3.0 and p["bodies.ball.velocity.0"].unit == "m/s"
    assert p["system.gravity.1"].default == -9.81
    assert p["contacts.left.e"].hi == 1.0 and p["contacts.left.e"].default == 0.9
    assert configured.solver["t_end"] == 2.0 and configured.solver["h"] == 1e-3
    units = spec.units
    assert units["ball.x"] == "m" and units["ball.vy"] == "m/s" and units["floor.gap"] == "m"
    assert units["floor.force"] == "N" and units["energy"] == "J"
    for path in (BALL, PENDULUM, CHAIN):
        spec = configure(path).spec
        assert set(spec.units) == set(spec.observables) and set(spec.plotted) <= set(spec.observables)
        assert 0 < len(spec.plotted) <= 9 and set(spec.error_observables) <= set(spec.observables)
    assert set(configure(CHAIN).spec.plotted) >= {"m3.y", "floor.gap", "energy"}


def test_dotted_overrides_change_the_model():
    scene = load_scene(BALL, {"bodies.ball.mass": 2.0, "contacts.floor.e": 0.3, "bodies.ball.position.1": 2.5,
                              "system.gravity.1": -1.0})
    model = scene.model
    assert float(model.body("ball").mass_) == 2.0
    np.testing.assert_array_equal(np.asarray(model.restitution), [0.3, 0.9, 0.9])
    np.testing.assert_array_equal(scene.q0, [0.0, 2.5])
    np.testing.assert_allclose(np.asarray(model.force(scene.q0, scene.v0, 0.0)), [0.0, -2.0])
    assert scene.parameters["bodies.ball.mass"] == 2.0


@pytest.mark.usefixtures("no_compilation")
def test_a_whole_vector_sets_its_components():
    configured = configure(BALL, {"bodies.ball.velocity": [-1.0, 2.0], "system.gravity": [0.0, -1.62]})
    assert configured.parameters["bodies.ball.velocity.0"] == -1.0
    assert configured.parameters["bodies.ball.velocity.1"] == 2.0
    assert configured.parameters["system.gravity.1"] == -1.62
    with pytest.raises(ConfigError, match=r"bodies.ball.velocity has the components bodies.ball.velocity.0, "
                                          r"bodies.ball.velocity.1; got \[1.0, 2.0, 3.0\]"):
        configure(BALL, {"bodies.ball.velocity": [1.0, 2.0, 3.0]})
    with pytest.raises(ConfigError, match=r"bodies.ball.velocity.1 must be a number, got str 'up'"):
        configure(BALL, {"bodies.ball.velocity": [1.0, "up"]})


def test_the_file_builds_the_model_a_python_system_builds():
    scene = load_scene(PENDULUM)
    system = System(2, gravity=[0.0, -9.81])
    for name, x in (("upper", 0.5), ("lower", 1.5)):
        system.add_body(name, RigidBody2D(1.0, 0.08333333333333333, [x, 0.0]))
    from nsga_jax.system import Pin

    system.add_joint("pivot", Pin("ground", "upper", at_a=[0.0, 0.0], at_b=[-0.5, 0.0]))
    system.add_joint("elbow", Pin("upper", "lower", at_a=[0.5, 0.0], at_b=[-0.5, 0.0]))
    system.add_contact("wall", PlaneContact("lower", [1.0, 0.0], [-0.6, 0.0], 0.5, points=[[0.5, 0.0]]))
    model = system.model()
    q0, v0 = model.initial_state()
    np.testing.assert_array_equal(scene.q0, q0)
    np.testing.assert_array_equal(scene.v0, v0)
    import equinox as eqx

    assert eqx.tree_equal(scene.model, model)  # the same parts, names, structure and numbers
    assert scene.model.linear_constraints is False


def test_a_config_may_name_a_system_file_with_dotted_parameters(tmp_path):
    config = tmp_path / "stiff_floor.toml"
    config.write_text(f'scene = "{BALL}"\n\n[parameters]\nbodies.ball.mass = 3.0\n\n'
                      '[parameters.contacts.floor]\ne = 0.1\n\n[solver]\nt_end = 0.5\n')
    configured = configure(config)
    assert configured.parameters["bodies.ball.mass"] == 3.0
    assert configured.parameters["contacts.floor.e"] == 0.1 and configured.solver["t_end"] == 0.5


def test_the_config_command_writes_a_config_that_reads_back(tmp_path, capsys):
    assert main(["config", str(BALL)]) == 0
    text = capsys.readouterr().out
    assert f'scene = "{BALL}"' in text and "bodies.ball.velocity.0 = 3.0" in text
    config = tmp_path / "again.toml"
    config.write_text(text.replace("bodies.ball.velocity.0 = 3.0", "bodies.ball.velocity.0 = -1.0"))
    assert configure(config).parameters["bodies.ball.velocity.0"] == -1.0


# --------------------------------------------------------------- validation

BAD_FILES = [
    # (source, old text, new text, what the message must say)
    (BALL, "[solver]", "[solvr]", r"unknown top-level table 'solvr'; allowed: system, bodies, joints"),
    (BALL, "dim = 2", "dim = 2\ncolour = 1", r"system: unknown key 'colour'; allowed: name, description"),
    (BALL, "mass = 0.5 ", "mas = 0.5 ", r"bodies.ball: unknown key 'mas' for type 'point_mass'; allowed: type, mass"),
    (BALL, 'normal = [0.0, 1.0]', 'normal = [0.0, 1.0]\nrestitution = 1', r"contacts.floor: unknown key 'restitution'"),
    (BALL, 'type = "point_mass"', 'type = "point_mas"', r"bodies.ball.type: unknown body type 'point_mas'; "
                                                        r"allowed: point_mass, rigid_body_2d, rigid_body_3d, "
                                                        r"bar, beam_2d, hex_solid"),
    (PENDULUM, 'type = "pin"', 'type = "hinge"', r"joints.pivot.type: unknown joint type 'hinge'; allowed: pin,"),
    (BALL, 'type = "plane"', 'kind = "plane"', r"contacts.floor: missing key 'type'; allowed types: plane, sphere"),
    (BALL, "mass = 0.5 ", 'mass = "heavy" ', r"bodies.ball.mass must be a number, got str 'heavy'"),
    (BALL, "velocity = [3.0, 0.0]", 'velocity = [3.0, true]', r"bodies.ball.velocity.1 must be a number, got bool"),
    (BALL, 'body = "ball"', "body = 1", r"contacts.floor.body must be a string, got int 1"),
    (PENDULUM, "dim = 2", "dim = 2.5", r"system.dim must be 1, 2 or 3"),
    (BALL, "h = 1e-3", 'h = "small"', r"solver.h \[s\] must be a number, got 'small'"),
    (BALL, "h = 1e-3", "step = 1e-3", r"solver: unknown key 'step'; allowed: scheme, h, t_end"),
    (BALL, "mass = 0.5 ", "mass = -0.5 ", r"bodies.ball.mass \[kg\] must be in \(0, inf\), got -0.5"),
    (BALL, "e = 0.8", "e = 1.5", r"contacts.floor.e must be in \[0, 1\], got 1.5"),
    (BALL, "mass = 0.5 ", "# ", r"bodies.ball: missing required key 'mass' \(point_mass\(mass, position"),
    (PENDULUM, 'origin = [-0.6, 0.0]\npoints', 'points', r"contacts.wall: missing required key 'origin'"),
    (BALL, 'body = "ball"', 'body = "bal"', r"contacts.floor.body = 'bal' names a body that does not exist; "
                                            r"bodies: ball \(and ground\)"),
    (PENDULUM, 'body_b = "lower"', 'body_b = "lowr"', r"joints.elbow.body_b = 'lowr' names a body that does not "
                                                      r"exist; bodies: upper, lower"),
    (CHAIN, 'body_b = "m2"', 'body_b = "m4"', r"forces.middle.body_b = 'm4' names a body"),
    (BALL, "position = [0.0, 1.0]", "position = [0.0, 0.05]", r"contacts.floor: initial penetration of 0.05 m"),
    (PENDULUM, "position = [1.5, 0.0]", "position = [1.6, 0.0]", r"joints.elbow: violated at the initial state "
                                                                 r"by 0.1 m"),
    (PENDULUM, "angle = 0.0                  # rad", "angular_velocity = 1.0",
     r"joints.pivot: the initial velocities violate it"),
    (PENDULUM, "at_b = [-0.5, 0.0]  ", "at_b = [-0.5, 0.0, 0.0]", r"joints.pivot: anchor b on "
                                                                          r"RigidBody2D: the body lives in 2"),
    (BALL, "position = [0.0, 1.0]", "position = [0.0, 1.0, 2.0]", r"bodies.ball: PointMass.velocity must be a "
                                                                  r"vector of 3"),
    (BALL, "gravity = [0.0, -9.81]", "gravity = [0.0, -9.81, 0.0]", r"system.gravity \[m/s\^2\] must have 2 "
                                                                    r"coordinates"),
    (BALL, "[bodies.ball]", "[bodies.ground]", r"bodies.ground: 'ground' is the fixed frame's name"),
]


@pytest.mark.usefixtures("no_compilation")
@pytest.mark.parametrize("source, old, new, match", BAD_FILES, ids=[c[3][:50] for c in BAD_FILES])
def test_a_bad_system_file_is_a_named_error(tmp_path, source, old, new, match):
    path = _variant(tmp_path, source, old, new)
    with pytest.raises(ConfigError, match=match) as err:
        configure(path)
    assert str(err.value).startswith(str(path))  # the file, then the dotted path
    assert "\n" not in str(err.value)


@pytest.mark.usefixtures("no_compilation")
@pytest.mark.parametrize("overrides, match", [
    ({"bodies.ball.mass": 0.0}, r"bodies.ball.mass \[kg\] must be in \(0, inf\), got 0.0"),
    ({"bodies.ball.mass": "x"}, r"bodies.ball.mass \[kg\] must be a number"),
    ({"bodies.ball.masss": 1.0}, r"unknown config key 'bodies.ball.masss' for scene 'ball_between_walls'"),
    ({"bodies.ball.position.1": 0.0}, r"contacts.floor: initial penetration of 0.1 m"),
])
def test_a_bad_override_is_a_named_error(overrides, match):
    with pytest.raises(ConfigError, match=match):
        configure(BALL, overrides)


@pytest.mark.usefixtures("no_compilation")
def test_a_built_in_scene_name_is_refused(tmp_path):
    path = _variant(tmp_path, BALL, "dim = 2", 'dim = 2\nname = "bouncing_ball"', name="mine.toml")
    with pytest.raises(ConfigError, match=r"the scene name 'bouncing_ball' is a built-in scene's"):
        configure(path)
    assert REGISTRY["bouncing_ball"].parameters["e"].default == 0.8  # untouched


@pytest.mark.usefixtures("no_compilation")
def test_a_changed_file_is_read_again(tmp_path):
    path = _variant(tmp_path, BALL, "mass = 0.5 ", "mass = 0.7 ", name="changing.toml")
    assert configure(path).parameters["bodies.ball.mass"] == 0.7
    path.write_text(path.read_text().replace("mass = 0.7 ", "mass = 0.125"))
    assert configure(path).parameters["bodies.ball.mass"] == 0.125


@pytest.mark.usefixtures("no_compilation")
@pytest.mark.parametrize("command, old, new, fragment", [
    (["run"], 'body = "ball"', 'body = "bal"', "contacts.floor.body = 'bal' names a body that does not exist"),
    (["run"], 'body = "ball"', 'body = "ground"',
     "contacts.floor: body = 'ground', the fixed frame; a contact needs a moving body (one of: ball)"),
    (["run"], "mass = 0.5 ", "mas = 0.5 ", "bodies.ball: unknown key 'mas'"),
    (["run"], 'type = "plane"', 'type = "wall"', "contacts.floor.type: unknown contact type 'wall'"),
    (["run", "--set", "bodies.ball.position.1=0.05"], "", "", "contacts.floor: initial penetration of 0.05 m"),
    (["run", "--set", "bodies.ball.mass=heavy"], "", "", "bodies.ball.mass [kg] must be a number, got 'heavy'"),
    (["sweep", "--grid", "contacts.floor.e=0:1:3"], "e = 0.8", 'e = "high"', "contacts.floor.e must be a number"),
    (["sweep", "--grid", "contacts.floor.e=0:2:3"], "", "", "contacts.floor.e must be in [0, 1], got 2.0"),
    (["identify", "--params", "bodies.ball.mass", "--synthetic"], "h = 1e-3", "h = -1e-3",
     "solver.h [s] must be in (0, inf), got -0.001"),
    (["identify", "--params", "bodies.ball.position", "--synthetic"], "", "",
     "--params: 'bodies.ball.position' is not a float parameter"),
    (["convergence", "--h", "1e-2", "--ref-h", "1e-3"], "[bodies.ball]", "[bodies.ball]\nspin = 1",
     "bodies.ball: unknown key 'spin'"),
])
def test_cli_refuses_a_bad_file_in_one_line(tmp_path, capsys, command, old, new, fragment):
    path = _variant(tmp_path, BALL, old, new, name="bad.toml")
    rc = main([command[0], str(path), *command[1:], "--out", str(tmp_path / "out")])
    assert rc == EXIT_INPUT
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("error: ") and fragment in err, err


BEAM = """
[system]
gravity = [0.0, -9.81]

[bodies.beam]
type = "beam_2d"
E = 2e9
nu = 0.3
rho = 1000.0
area = 1e-4
second_moment = 1e-9
length = 1.0
n_elements = 4

[joints.clamp]
type = "weld"
body_a = "ground"
body_b = "beam"
node_b = 0

[contacts.stop]
type = "plane"
body = "beam"
normal = [0.0, 1.0]
origin = [0.0, -0.1]
nodes = [-1]
e = 0.0
"""


@pytest.mark.usefixtures("no_compilation")
def test_a_flexible_body_has_structural_parameters_and_a_tip(tmp_path):
    path = tmp_path / "cantilever.toml"
    path.write_text(BEAM)
    spec = configure(path).spec
    assert spec.parameters["bodies.beam.n_elements"].kind == "int"
    assert spec.parameters["joints.clamp.node_b"].kind == "int"
    assert "contacts.stop.nodes" not in spec.parameters  # a node list is structure fixed by the file
    assert {"beam.tip_x", "beam.tip_y", "beam.tip_theta", "beam.tip_omega", "clamp.violation"} <= set(spec.units)
    scene = load_scene(path, {"bodies.beam.n_elements": 6})
    assert scene.model.n_dof == 21 and scene.q0[-3] == 1.0  # the tip node at x = L
    rc = main(["sweep", str(path), "--grid", "contacts.stop.e=0:1:3,bodies.beam.n_elements=4;8",
               "--out", str(tmp_path / "out")])
    assert rc == EXIT_INPUT


def test_bench_takes_a_system_file():
    from nsga_jax._cli import _bench_scene

    assert _bench_scene(str(CHAIN)) == "spring_chain"
    assert _bench_scene("bouncing_ball") == "bouncing_ball"
    with pytest.raises(ConfigError, match="not the config"):
        _bench_scene(str(Path(__file__).resolve().parents[1] / "nsga_jax" / "configs" / "bouncing_ball.toml"))


# --------------------------------------------------------------------- runs


def test_a_system_file_runs(tmp_path):
    scene = load_scene(BALL, {"t_end": 0.5, "h": 1e-2, "contacts.right.origin.0": 1.2})
    sol = scene.run()
    obs = sol.observables
    assert sol.stats["failed_steps"] == 0
    t = np.asarray(sol.ts)
    x = np.asarray(obs["ball.x"])
    free = t <= (1.1 - 0.0) / 3.0  # before the ball reaches the right wall (radius 0.1)
    np.testing.assert_allclose(x[free], 3.0 * t[free], atol=1e-12)  # no force along x until then
    np.testing.assert_allclose(np.asarray(obs["ball.vx"])[free], 3.0)
    np.testing.assert_allclose(np.asarray(obs["floor.gap"]), np.asarray(obs["ball.y"]) - 0.1, atol=1e-14)
    np.testing.assert_allclose(np.asarray(obs["right.gap"]), 1.2 - x - 0.1, atol=1e-14)
    assert np.asarray(obs["floor.gap"]).min() > -1e-10
    assert float(np.asarray(obs["floor.force"]).max()) > 0.0  # the floor pushed at the bounce
    energy = np.asarray(obs["energy"])
    assert abs(energy[0] - (0.5 * 0.5 * 9.0 + 0.5 * 9.81 * 1.0)) < 1e-12


@pytest.mark.parametrize("path", [PENDULUM, CHAIN])
def test_the_examples_run(path):
    scene = load_scene(path, {"t_end": 0.05})
    sol = scene.run()
    assert sol.stats["failed_steps"] == 0 and sol.stats["max_bilateral_violation_position"] < 1e-8
    for name, y in sol.observables.items():
        assert np.all(np.isfinite(np.asarray(y))), name
    if path == PENDULUM:
        assert np.asarray(sol.observables["elbow.violation"]).max() < 1e-8


def test_cli_runs_a_system_file(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(["run", str(BALL), "--t-end", "0.05", "--h", "0.01", "--set", "bodies.ball.mass=2.0",
               "--out", str(out), "--quiet"])
    assert rc == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["scene"] == "ball_between_walls" and summary["parameters"]["bodies.ball.mass"] == 2.0
    data = np.load(out / "trajectory.npz")
    assert "ball.vy" in data and "floor.gap" in data and data["q"].shape == (6, 2)
    np.testing.assert_allclose(data["ball.x"], 3.0 * data["t"], atol=1e-12)
    assert (out / "observables.png").stat().st_size > 1000


def test_a_sweep_over_a_dotted_path(tmp_path, capsys):
    out = tmp_path / "sweep"
    rc = main(["sweep", str(BALL), "--grid", "contacts.floor.e=0.2;0.9", "--set", "t_end=0.6",
               "--set", "h=0.01", "--out", str(out), "--quiet"])
    assert rc == 0
    import csv

    rows = list(csv.DictReader(open(out / "sweep.csv")))
    assert [float(r["contacts.floor.e"]) for r in rows] == [0.2, 0.9]
    # after the bounce (t ~ 0.43 s) the ball rises faster off the more elastic floor
    assert float(rows[1]["ball.vy_final"]) > float(rows[0]["ball.vy_final"]) > 0.0


def test_gradient_of_a_dotted_parameter_matches_finite_differences():
    import jax

    import nsga_jax as nj

    name = "contacts.floor.e"
    params, build = parametrize(str(BALL), names=[name])

    def final_height(p):  # after the bounce at t ~ 0.43 s
        model, q0, v0, observables = build(p)
        sol = nj.integrate(model, nj.DS(), 0.0, 0.5, 1e-2, q0, v0)
        return observables(sol)["ball.y"][-1]

    grad = float(jax.jit(jax.grad(final_height))(params)[name])
    height = jax.jit(final_height)
    eps = 1e-6
    fd = (float(height({name: params[name] + eps})) - float(height({name: params[name] - eps}))) / (2 * eps)
    assert math.isfinite(grad) and grad > 0.05  # a more elastic floor: higher after the bounce
    assert abs(grad - fd) <= 1e-6 * max(1.0, abs(fd)), (grad, fd)


def test_identify_recovers_a_dotted_parameter(tmp_path, capsys):
    out = tmp_path / "identify"
    rc = main(["identify", str(BALL), "--params", "contacts.floor.e", "--synthetic", "--initial",
               "contacts.floor.e=0.6", "--observables", "ball.y", "--t-end", "0.6", "--set", "h=0.01",
               "--max-steps", "30", "--out", str(out)])
    assert rc == 0
    assert "contacts.floor.e: initial 0.6 -> recovered 0.8" in capsys.readouterr().out


def test_convergence_of_a_system_file(tmp_path, capsys):
    out = tmp_path / "convergence"
    rc = main(["convergence", str(BALL), "--h", "2e-2,1e-2", "--ref-h", "5e-3", "--t-end", "0.6", "--out", str(out)])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "ds h = 0.02" in printed and "ball.x" in printed and "ball.y" in printed  # positions by default
    assert (out / "study.csv").exists()


SOLID = """\
[system]
dim = 3
gravity = [0.0, 0.0, -9.81]

[bodies.cube]
type = "hex_solid"
size = [0.1, 0.1, 0.1]
divisions = [2, 2, 2]
E = 90.0
nu = 0.3
rho = 1.0
position = [0.0, 0.0, 0.2]

[contacts.floor]
type = "plane"
body = "cube"
normal = [0.0, 0.0, 1.0]
origin = [0.0, 0.0, 0.0]
e = 0.0
nodes = "bottom"
"""


@pytest.mark.usefixtures("no_compilation")
def test_a_solid_face_names_its_contact_nodes(tmp_path):
    path = tmp_path / "solid.toml"
    path.write_text(SOLID)
    scene = load_scene(path)
    assert scene.model.n_unilateral == 9 and scene.model.n_dof == 81
    np.testing.assert_allclose(scene.model.unilateral(scene.q0), 0.15, rtol=1e-14)  # the bottom face, 0.05 m below
    path.write_text(SOLID.replace('"bottom"', '"bottm"'))
    with pytest.raises(ConfigError, match=r"contacts\.floor: HexSolid has no face 'bottm'; its faces: left"):
        load_scene(path)


def test_a_written_config_names_its_scene_file_from_anywhere(tmp_path, capsys, monkeypatch):
    """nsga-jax config FILE.py > elsewhere/x.toml, run from a relative path, names
    the file by its absolute path: the config reads back from another folder.
    A config whose scene file is missing says so, not that it is a config."""
    example = Path(__file__).resolve().parents[1] / "nsga_jax" / "examples" / "double_pendulum.py"
    (tmp_path / "here").mkdir()
    (tmp_path / "there").mkdir()
    monkeypatch.chdir(tmp_path / "here")
    assert main(["config", os.path.relpath(example)]) == 0
    text = capsys.readouterr().out
    assert f'scene = "{example}"' in text
    (tmp_path / "there" / "dp.toml").write_text(text)
    monkeypatch.chdir(tmp_path)
    assert configure("there/dp.toml").spec.name == configure(example).spec.name
    (tmp_path / "there" / "missing.toml").write_text('scene = "no_such_scene.toml"\n')
    with pytest.raises(ConfigError, match=r"scene or config file '.*no_such_scene.toml' does not exist \(a config's "
                                          r"scene is read relative to the config's folder"):
        configure(tmp_path / "there" / "missing.toml")
