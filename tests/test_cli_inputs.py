"""Every option of every subcommand, given a malformed value, ends with exit 2
and one line ``error: ...`` naming the option or field, with no traceback and
before anything is compiled."""

import argparse

import pytest

from nsga_jax._cli import EXIT_INPUT, command_parser, main

MALFORMED = ("abc", "-1", "nan", "1e999", "")
"""Values tried on every option that takes one (those an option legitimately
accepts are left out per option below)."""

ACCEPTS = {
    "--out": set(MALFORMED),  # any text is a path; an existing file is tried instead
    "--observables": set(),
    "--first-step-limit": {"1e999"},  # inf: no limit
}

BASE = {
    "run": ["run", "bouncing_ball"],
    "convergence": ["convergence", "bouncing_ball", "--h", "1e-2", "--ref", "exact"],
    "identify": ["identify", "bouncing_ball", "--params", "e", "--synthetic"],
    "sweep": ["sweep", "bouncing_ball", "--grid", "e=0.5"],
    "bench": ["bench", "--scenes", "bouncing_ball"],
    "config": ["config", "bouncing_ball"],
}

EXCLUSIVE = {"--ref-h": "--ref", "--ref": "--ref-h", "--data": "--synthetic"}
"""Options of a mutually exclusive group: testing one drops the other from the base command."""


def subcommands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in command_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def value_options(parser: argparse.ArgumentParser) -> list[str]:
    return [a.option_strings[-1] for a in parser._actions
            if a.option_strings and a.nargs != 0 and not isinstance(a, argparse._HelpAction)]


CASES = [(cmd, option, value) for cmd, parser in subcommands().items() if cmd in BASE
         for option in value_options(parser) for value in MALFORMED if value not in ACCEPTS.get(option, set())]
CASES += [(cmd, "--out", "<existing file>") for cmd, parser in subcommands().items()
          if cmd in BASE and "--out" in value_options(parser)]
CASES += [("config", None, "abc"), ("run", None, "no_such_scene"), ("sweep", None, "missing.toml")]


def command(cmd: str, option: str | None, value: str, tmp_path) -> list[str]:
    base = list(BASE[cmd])
    if option is None:  # the positional scene
        return [cmd, value, *base[2:]] + ([] if cmd == "config" else ["--out", str(tmp_path / "out")])
    for drop in (option, EXCLUSIVE.get(option)):
        if drop in base:
            i = base.index(drop)
            takes_value = drop not in ("--synthetic",)
            del base[i:i + 1 + takes_value]
    if value == "<existing file>":
        value = str(tmp_path / "a_file")
        (tmp_path / "a_file").write_text("not a folder\n")
    args = base + [option, value]
    if option != "--out" and "--out" in value_options(subcommands()[cmd]):
        args += ["--out", str(tmp_path / "out")]
    return args


pytestmark = pytest.mark.usefixtures("no_compilation")  # a malformed value is refused before compiling


def test_every_value_option_is_covered():
    covered = {(c, o) for c, o, _ in CASES}
    for cmd, parser in subcommands().items():
        if cmd in BASE:
            for option in value_options(parser):
                assert (cmd, option) in covered, (cmd, option)
    assert len(CASES) > 150


@pytest.mark.parametrize("cmd, option, value", CASES)
def test_malformed_value_exits_2_with_one_error_line(cmd, option, value, tmp_path, capsys):
    args = command(cmd, option, value, tmp_path)
    assert main(args) == EXIT_INPUT, args
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), (args, err)
    assert "Traceback" not in err[0]
