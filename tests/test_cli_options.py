"""The command line's surface: help written for users, a help text for every
option of every command, a quick default ``bench``, ``--no-plots``, refused
runs that leave no folder behind, and ``--record-every`` thinning what an
interrupted run writes."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from nsga_jax import _bench as bench_module
from nsga_jax import _progress as progress
from nsga_jax._chunks import load_chunks
from nsga_jax._cli import EXIT_INPUT, EXIT_INTERRUPTED, main
from nsga_jax._cli_options import BENCH_SCENES, command_parser


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
    assert set(commands) == {"run", "animate", "convergence", "identify", "sweep", "bench", "scenes", "config"}
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


def _interrupt_after(monkeypatch, chunks: int) -> None:
    """Ctrl-C as the run reports its ``chunks``-th finished chunk."""
    seen = []
    original = progress.Progress.chunk

    def chunk(self, steps_done: int, last: bool) -> None:
        original(self, steps_done, last)
        seen.append(steps_done)
        if len(seen) == chunks:
            raise KeyboardInterrupt

    monkeypatch.setattr(progress.Progress, "chunk", chunk)


@pytest.mark.parametrize("k", [1, 10])
def test_an_interrupted_run_writes_the_kept_steps_only_in_few_files(k, tmp_path, monkeypatch, capsys):
    _interrupt_after(monkeypatch, 4)
    out = tmp_path / f"every_{k}"
    code = main(["run", "bouncing_ball", "--h", "1e-4", "--t-end", "100", "--chunk", "256", "--record-every", str(k),
                 "--out", str(out), "--quiet"])
    assert code == EXIT_INTERRUPTED
    files = sorted((out / "partial").glob("chunk_*.npz"))
    kept = load_chunks(out)
    steps = np.arange(1, 4 * 256 + 1)
    expected = steps[steps % k == 0]  # 1024 rows with every step, 102 with every 10th
    np.testing.assert_allclose(kept["t"], expected * 1e-4, rtol=1e-12)
    assert len(files) == 1  # four chunks, one file, written at the interruption
    assert f"interrupted: the records of {len(expected)} step(s)" in capsys.readouterr().err
    assert json.loads((out / "run.json").read_text())["solver"]["record_every"] == k
