"""The command line's surface: help written for users, a help text for every
option of every command, a quick default ``bench``."""

from __future__ import annotations

import argparse

import pytest

from nsga_jax import bench as bench_module
from nsga_jax.cli import main
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
