"""Identification on synthetic data: the parameters that made the data are
recovered from 25-30 % off (noise-free to 1e-4, 1 % noise to 1 %); the command
line writes identification.json and plots; bad input is refused."""

import json

import jax.numpy as jnp
import numpy as np
import pytest

import nsga_jax as nj
from nsga_jax import ConfigError
from nsga_jax._cli import main
from nsga_jax._fit_steps import COMPASS, compass_search
from nsga_jax._identify import NOISE_MARGIN, Data, Identification, identify, synthetic_data

BALL = {"t_end": 1.0, "h": 2e-3}  # one impact (t ~ 0.45 s), 500 steps
TRUE = {"e": 0.8, "height": 1.0}
START = {"e": 0.6, "height": 1.3}


@pytest.mark.parametrize("noise, tol", [(0.0, 1e-4), (0.01, 1e-2)], ids=["noise-free", "1% noise"])
def test_ball_restitution_and_height_recovered(noise, tol):
    data = synthetic_data("bouncing_ball", {**BALL, **TRUE}, ["z"], noise=noise, seed=3, every=4)
    result = identify("bouncing_ball", ["e", "height"], data, overrides=BALL, initial=START, true=TRUE)
    summary = result.summary()
    assert summary["initial"] == START
    for k, v in TRUE.items():
        assert abs(result.recovered[k] / v - 1) < tol, (k, result.recovered[k])
        assert summary["relative_error"][k] < tol
    assert result.losses[-1] < 1e-3 * result.losses[0]
    assert result.iterations >= 2 and result.evaluations >= result.iterations
    assert np.max(np.abs(result.fitted["z"] - data.values["z"])) < 0.05 + 4 * noise


def test_adam_also_descends():
    data = synthetic_data("bouncing_ball", {**BALL, **TRUE}, ["z"], every=4)
    result = identify("bouncing_ball", ["e"], data, overrides={**BALL, "height": 1.0}, initial={"e": 0.6},
                      optimizer="adam", max_steps=60, learning_rate=0.02)
    assert result.losses[-1] < 0.05 * result.losses[0]
    assert abs(result.recovered["e"] - 0.8) < 0.02


def test_data_files_round_trip(tmp_path):
    data = Data(t=np.linspace(0, 1, 11), values={"z": np.linspace(1, 0, 11)})
    for name in ("d.csv", "d.npz"):
        back = Data.load(data.save(tmp_path / name))
        np.testing.assert_array_equal(back.t, data.t)
        np.testing.assert_array_equal(back.values["z"], data.values["z"])


@pytest.mark.parametrize("values, match", [
    ({"z": np.ones(10)}, "shape"),
    ({"z": np.full(11, np.nan)}, "non-finite"),
    ({}, "no observable"),
])
def test_bad_data_is_refused(values, match):
    with pytest.raises(ConfigError, match=match):
        Data(t=np.linspace(0, 1, 11), values=values).check()


def test_unknown_observable_and_parameter_are_refused():
    data = Data(t=np.linspace(0, 1, 11), values={"height_of_ball": np.ones(11)})
    with pytest.raises(ConfigError, match="unknown observable 'height_of_ball'"):
        identify("bouncing_ball", ["e"], data)
    data = Data(t=np.linspace(0, 1, 11), values={"z": np.ones(11)})
    with pytest.raises(ConfigError, match="not a float parameter"):
        identify("bouncing_ball", ["stiffness"], data)


def test_cli_identify_synthetic_then_from_file(tmp_path, capsys):
    out = tmp_path / "id"
    rc = main(["identify", "bouncing_ball", "--params", "e", "--synthetic", "--true", "e=0.8",
               "--initial", "e=0.6", "--t-end", "0.8", "--h", "2e-3", "--every", "4", "--out", str(out)])
    assert rc == 0
    report = json.loads((out / "identification.json").read_text())
    for key in ("true", "initial", "recovered", "iterations", "wall_time_s", "relative_error"):
        assert key in report
    assert report["true"] == {"e": 0.8} and report["initial"] == {"e": 0.6}
    assert abs(report["recovered"]["e"] - 0.8) < 1e-4
    for png in ("loss.png", "fit.png"):
        assert (out / png).stat().st_size > 1000
    assert "recovered" in capsys.readouterr().out
    # the synthetic data were written; fit them again as measured data
    out2 = tmp_path / "id2"
    rc = main(["identify", "bouncing_ball", "--params", "e", "--data", str(out / "data.csv"),
               "--initial", "e=0.7", "--h", "2e-3", "--out", str(out2)])
    assert rc == 0
    report = json.loads((out2 / "identification.json").read_text())
    assert "true" not in report and abs(report["recovered"]["e"] - 0.8) < 1e-4


@pytest.mark.parametrize("args, match", [
    (["--params", "e", "--synthetic", "--true", "height=1"], "not in --params"),
    (["--params", "e", "--synthetic", "--true", "e=1.5"], "e must be in"),
    (["--params", "e", "--synthetic", "--noise", "2"], "--noise"),
    (["--params", "e", "--data", "missing.csv"], "does not exist"),
])
def test_cli_identify_bad_input(args, match, capsys, tmp_path):
    assert main(["identify", "bouncing_ball", *args, "--out", str(tmp_path)]) == 2
    assert match in capsys.readouterr().err


def test_a_start_30_percent_above_recovers_the_restitution():
    """The fit that once stopped at e = 9e-17 reporting success (its first step
    clipped to e = 0, where the gradient vanishes): from e = 0.82 for a true
    0.63, e is recovered within 1 %, and the fit says it converged."""
    data = synthetic_data("bouncing_ball", {"e": 0.63}, ["z"])
    result = identify("bouncing_ball", ["e"], data, initial={"e": 0.82})
    assert abs(result.recovered["e"] / 0.63 - 1) < 1e-2
    assert result.converged and result.summary()["converged"]


def test_a_fit_stopped_on_a_flat_bound_is_reported_as_failed(monkeypatch, tmp_path, capsys):
    """With unbounded steps the first one lands on the bound e = 0 (no rebound,
    no gradient): the fit must say so, and the command line exit 1."""
    import nsga_jax._identify as identify_module

    monkeypatch.setattr(identify_module, "MAX_STEP", 10.0)
    data = synthetic_data("bouncing_ball", {"e": 0.63}, ["z"])  # the scene's defaults: 3 s at h = 1e-3 s
    result = identify("bouncing_ball", ["e"], data, initial={"e": 0.82})
    assert result.recovered["e"] == 0.0 and result.stop == "bound" and not result.converged
    assert "bound" in result.stop_message and result.at_bounds == ["e"]
    out = tmp_path / "id"
    rc = main(["identify", "bouncing_ball", "--params", "e", "--synthetic", "--true", "e=0.63", "--initial", "e=0.82",
               "--out", str(out)])
    assert rc == 1
    assert "error: the fit did not converge: stopped because it stopped on a bound" in capsys.readouterr().err
    report = json.loads((out / "identification.json").read_text())
    assert report["converged"] is False and report["stopped_by"] == "bound"


def test_dotted_observable_names_survive_a_csv_round_trip(tmp_path):
    """A system's observables are named part.quantity: the CSV header keeps the
    dots, so identify finds them (the check after the observables' is the
    parameter's, which this one fails)."""
    data = Data(t=np.linspace(0, 1, 11), values={"lower.theta": np.linspace(1, 0, 11), "upper.x": np.ones(11)})
    back = Data.load(data.save(tmp_path / "d.csv"))
    assert list(back.values) == ["lower.theta", "upper.x"]
    np.testing.assert_array_equal(back.values["lower.theta"], data.values["lower.theta"])
    with pytest.raises(ConfigError, match="not a float parameter"):
        identify("configs/systems/double_pendulum_wall.toml", ["no_such_parameter"], back)


@pytest.mark.parametrize("text, match", [
    ("", "empty"),
    ("t,z,z\n0,1,2\n", "distinct"),
    ("t,z\n0,1\n1\n", "line 3: 1 values"),
    ("t,z\n0,abc\n", "must be a number"),
])
def test_bad_csv_files_are_refused_by_name(tmp_path, text, match):
    path = tmp_path / "d.csv"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        Data.load(path)


def test_noise_is_estimated_from_the_data_alone():
    """σ of white noise on a bouncing ball's heights is recovered to 10 % by the
    data's own neighbour residuals, and noise-free heights give σ ~ round-off
    (the parabolas' curvature is constant between impacts)."""
    t = np.linspace(0.0, 3.0, 3001)
    z = np.abs(np.sin(2.0 * t)) * (1.0 - 0.1 * t)  # kinks where it bounces
    rng = np.random.default_rng(0)
    noisy = Data(t=t, values={"z": z + 0.003 * rng.normal(size=t.size)})
    assert noisy.noise_std()["z"] == pytest.approx(0.003, rel=0.1)
    parabola = Data(t=t, values={"z": 1.0 - 0.5 * 9.81 * (t % 0.5) ** 2})
    assert parabola.noise_std()["z"] < 1e-12


@pytest.mark.slow
def test_a_fit_at_the_noise_floor_is_converged_whichever_adjoint():
    """1 % noise on the ball's heights: both adjoints end at the data's noise
    floor (estimated from the data alone, 1e-4 of the normalised loss) and say
    they converged, with e within 0.1 % (the noise's own scatter)."""
    data = synthetic_data("bouncing_ball", {"e": 0.63, "height": 1.0}, ["z"], noise=0.01, seed=1)
    for adjoint in (nj.DiscreteAdjoint(), nj.ImpactTimeAdjoint()):
        result = identify("bouncing_ball", ["e"], data, overrides={"height": 1.0}, initial={"e": 0.819},
                          adjoint=adjoint)
        assert result.noise_floor == pytest.approx(1e-4, rel=0.1)
        assert result.losses[-1] < NOISE_MARGIN * result.noise_floor
        assert result.converged, result.stop_message
        assert abs(result.recovered["e"] / 0.63 - 1) < 1e-3


def _fake_evaluate(loss):
    """An ``evaluate`` of one scaled parameter ``x`` for the search helpers."""
    def evaluate(u):
        return (loss(float(u["x"])), {}), {"x": 0.0}
    return evaluate


def _advance(u, step, alpha):
    return {k: jnp.clip(u[k] + alpha * step[k], 0.0, 2.0) for k in u}


@pytest.mark.parametrize("loss, x, found", [
    (lambda x: abs(x - 1.0) + (0.1 if x > 1.0 else 0.0), 1.0, "minimum"),  # a kink with a jump
    (lambda x: 0.0 if x < 1.0 + 1e-3 else 1.0, 1.0, "flat"),  # a plateau
    (lambda x: (x - 1.5) ** 2, 1.0, 1.01),  # smooth, still falling toward 1.5: the largest move
    (lambda x: (x - 1.00002) ** 2, 1.0, 1.00001),  # a minimum 2e-5 away: the move of 1e-5
    (lambda x: x, 0.0, "minimum"),  # against the lower bound, the loss rising inside
])
def test_a_failed_line_search_searches_the_compass_until_a_minimum(loss, x, found):
    accepted, evaluations, flat = compass_search(_fake_evaluate(loss), _advance, {"x": jnp.asarray(x)}, loss(x), ["x"])
    if isinstance(found, str):
        assert accepted is None and flat is (found == "flat")
        assert evaluations == (len(COMPASS) if x == 0.0 else 2 * len(COMPASS))
    else:
        assert float(accepted[0]["x"]) == pytest.approx(found, abs=1e-12) and accepted[1] < loss(x)


def test_stops_name_what_they_mean():
    base = dict(names=["e"], initial={"e": 0.8}, recovered={"e": 0.63}, true=None, losses=[1.0, 1e-4],
                iterations=5, evaluations=20, wall_time_s=1.0, compile_time_s=1.0)
    for stop, converged, says in [("minimum", True, "local minimum of the simulated loss"),
                                  ("noise", True, "noise floor"), ("flat", False, "the loss is flat here"),
                                  ("max_steps", False, "iteration cap")]:
        result = Identification(stop=stop, **base)
        assert result.converged is converged and says in result.stop_message
