"""The command line's surface: help written for users, a help text for every
option of every command, a quick default ``bench``, ``--no-plots``, refused
runs that leave no folder behind."""

from __future__ import annotations

import argparse

import pytest

from nsga_jax import bench as bench_module
from nsga_jax.cli import EXIT_INPUT, main
from nsga_jax.cli_options import BENCH_SCENES, command_parser


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    return next(a.choices for a in parser._actions if isinstance(a, argparse._SubParsersAction))


def test_top_level_help_speaks_to_users(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "Nonsmooth dynamics of multibody systems" in out and "nsga-jax config --list" in out
    for note in ("Importing", "JAX:", "argparse", "module", "``"):  # the module docstring's notes for maintainers
        assert note not in out, note


def test_every_option_of_every_command_has_help():
    parser = command_parser()
    commands = _subparsers(parser)
    assert set(commands) == {"run", "convergence", "identify", "sweep", "bench", "scenes", "config"}
    missing = []
    for name, sub in [("nsga-jax", parser), *commands.items()]:
        for action in sub._actions:
            if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            if not (action.help or "").strip() or action.help == argparse.SUPPRESS:
                missing.append(f"{name} {'/'.join(action.option_strings) or action.dest}")
    assert not missing, missing


def test_bench_defaults_to_a_quick_bench_and_all_asks_for_every_scene(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(bench_module, "bench", lambda scenes, batches, dtypes, **kw: calls.append(
        (scenes, batches, dtypes, kw["scheme"])) or [])
    assert main(["bench", "--out", str(tmp_path / "quick")]) == 0
    assert calls[-1] == ([BENCH_SCENES], [1, 64], ["float64"], "ds")
    assert main(["bench", "--scenes", "all", "--batch", "1,64,1024", "--dtype", "float64,float32",
                 "--out", str(tmp_path / "all")]) == 0
    assert calls[-1] == (None, [1, 64, 1024], ["float64", "float32"], "ds")  # None: every built-in scene


COMMANDS = {
    "run": ["run", "bouncing_ball", "--t-end", "0.2", "--quiet"],
    "sweep": ["sweep", "bouncing_ball", "--grid", "e=0.2;0.8", "--set", "t_end=0.2", "--quiet"],
    "convergence": ["convergence", "bouncing_ball", "--h", "1e-2,5e-3", "--ref", "exact", "--t-end", "0.6"],
    "identify": ["identify", "bouncing_ball", "--params", "e", "--synthetic", "--true", "e=0.7", "--initial",
                 "e=0.6", "--t-end", "0.6", "--h", "1e-2", "--max-steps", "2"],
}
"""Each command that draws plots, on the ball, short."""


@pytest.mark.parametrize("name", COMMANDS)
def test_no_plots_writes_the_data_and_no_png(name, tmp_path):
    out = tmp_path / name
    assert main([*COMMANDS[name], "--no-plots", "--out", str(out)]) in (0, 1)  # identify may stop unconverged
    files = sorted(p.name for p in out.rglob("*") if p.is_file())
    assert files and not [f for f in files if f.endswith(".png")], files
    assert any(f.endswith((".npz", ".csv", ".json")) for f in files)


@pytest.mark.parametrize("existed", [False, True])
def test_a_run_refused_after_its_checks_leaves_no_folder(tmp_path, capsys, existed):
    out = tmp_path / "new" / "ball"
    if existed:
        out.mkdir(parents=True)
    # its records would not fit: refused by simulate, after the folder was claimed
    assert main(["run", "bouncing_ball", "--h", "1e-12", "--t-end", "1", "--out", str(out)]) == EXIT_INPUT
    assert "records of 1,000,000,000,000 steps" in capsys.readouterr().err
    if existed:  # the user's folder stays, empty
        assert out.is_dir() and not any(out.iterdir())
    else:
        assert not (tmp_path / "new").exists()


def test_a_run_refused_by_its_first_step_claims_no_folder(tmp_path, capsys):
    out = tmp_path / "box"
    assert main(["run", "rigid_box", "--first-step-limit", "1e-300", "--out", str(out)]) == EXIT_INPUT
    assert "is estimated at" in capsys.readouterr().err
    assert not out.exists()
