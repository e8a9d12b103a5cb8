"""The command line's options: one argparse parser per subcommand, with
one-line errors (``error: ...``, exit 2) instead of a usage block, and a
help text for every option.

Importing this module loads no JAX: ``nsga-jax --help`` answers at once."""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import cast

from ._results import ConfigError
from ._validation import IMPACT_LAWS, IMPACT_TIMINGS, SCHEME_NAMES

CACHE_ENV = "NSGA_JAX_CACHE"

DESCRIPTION = ("Nonsmooth dynamics of multibody systems (rigid and flexible bodies, joints, impacts, Coulomb "
               "friction) with the decoupled nonsmooth generalized-alpha scheme: simulate a scene, measure "
               "convergence, sweep parameters, fit parameters to data, benchmark.")
"""What ``nsga-jax --help`` says first."""

EPILOG = ("`nsga-jax COMMAND --help` lists a command's options. `nsga-jax scenes` lists the built-in scenes; "
          "`nsga-jax config --list` the configs and example scenes shipped with the package, which every "
          "command reads by name from any folder (e.g. `nsga-jax run configs/rigid_box.toml`). Bad input is "
          "refused with one line `error: ...` (exit status 2).")
"""What ``nsga-jax --help`` says last."""

BENCH_SCENES = "impacting_bar"
"""``nsga-jax bench``'s default scene: one, so that the bench without options takes a minute or two."""


class OneLineErrorParser(argparse.ArgumentParser):
    """argparse with one-line errors (``error: ...``, exit 2) instead of a
    usage block."""

    def error(self, message: str):
        raise ConfigError(f"{self.prog}: {message} (see {self.prog} --help)")


def command_parser() -> argparse.ArgumentParser:
    """The parser of ``nsga-jax`` and every subcommand."""
    p = OneLineErrorParser(prog="nsga-jax", description=DESCRIPTION, epilog=EPILOG)
    p.add_argument("--version", action="version", version=f"%(prog)s {package_version()}",
                   help="print the installed version and exit")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    cached = argparse.ArgumentParser(add_help=False)
    cached.add_argument("--no-cache", action="store_true",
                        help="compile afresh and keep nothing on disk (default: compiled programs are kept in "
                             f"${CACHE_ENV} or ~/.cache/nsga_jax/xla, and a later run of the same scene structure, "
                             "with any h and parameter values, loads them instead of compiling)")
    plotted = argparse.ArgumentParser(add_help=False)
    plotted.add_argument("--no-plots", action="store_true",
                         help="write no PNG plots, only the data files (faster: no figure is drawn)")
    # typeshed wants parents of the subparsers' own class (OneLineErrorParser); argparse copies any parser's arguments
    parents = cast(list[OneLineErrorParser], [cached, plotted])

    run = sub.add_parser("run", help="simulate a built-in scene or a TOML config", parents=parents)
    run.add_argument("scene", help="scene name (see `nsga-jax scenes`), a .toml config or system file, or a .py "
                                   "file that registers a scene (file.py:NAME picks one of several)")
    run.add_argument("--h", type=float, help="step size [s]")
    run.add_argument("--t-end", type=float, help="end time [s]")
    run.add_argument("--rho-inf", type=float, help="spectral radius at infinity, in [0, 1]")
    run.add_argument("--scheme", choices=SCHEME_NAMES, help="time integration scheme")
    run.add_argument("--impact-law", choices=IMPACT_LAWS,
                     help="impact law with restitution (default newton): energetic caps Newton's restitution so "
                          "that a frictional impact cannot create energy (Kane's paradox; ds and dsn; "
                          "docs/friction.md)")
    run.add_argument("--impacts", choices=IMPACT_TIMINGS,
                     help="where an impact is applied (default end, the paper's): instants resolves each impact "
                          "at its instant inside the step (ds and dsn; docs/scheme.md)")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                     help="override a config key (repeatable), e.g. --set e=0.5 or, for a system file, "
                          "--set bodies.ball.mass=2")
    run.add_argument("--dtype", choices=("float64", "float32"), help="floating-point precision (default float64)")
    run.add_argument("--record-every", type=int, metavar="K",
                     help="keep every K-th step (and the last) in memory, in DIR/partial/ while the run goes and "
                          "in trajectory.npz; the statistics still cover every step (flat memory and small files "
                          "for long runs)")
    run.add_argument("--no-throw", action="store_true",
                     help="keep going past an unconverged step and mark it in the results")
    run.add_argument("--out", type=Path, help="output folder (default: nsga_out/<scene>, or nsga_out/<scene>_2, ... "
                                              "when it holds an earlier run); a folder holding an earlier run is "
                                              "refused unless --overwrite")
    run.add_argument("--overwrite", action="store_true", help="replace the earlier run in --out")
    run.add_argument("--strict", action="store_true",
                     help="fail (exit 1) when the energy rises at an impact past its tolerance (default: a warning)")
    run.add_argument("--chunk", type=int, default=None, help="steps per compiled chunk")
    run.add_argument("--quiet", action="store_true", help="no progress output")
    run.add_argument("--animate", action="store_true",
                     help="also draw the run: DIR/animation.gif and DIR/animation.html (as `nsga-jax animate DIR`)")
    _first_step_limit(run, "a run")

    conv = sub.add_parser("convergence", help="error (eq. 52), iterations and run time against the step size",
                          parents=parents)
    conv.add_argument("scene", help="scene name, .toml config or system file")
    conv.add_argument("--scheme", default="ds", help="comma-separated schemes (ds, dsn, cs, mj)")
    conv.add_argument("--h", required=True, help="comma-separated step sizes [s]")
    ref = conv.add_mutually_exclusive_group(required=True)
    ref.add_argument("--ref-h", type=float, help="reference: a run at this (much smaller) step")
    ref.add_argument("--ref", choices=("exact",), help="reference: the scene's exact solution")
    conv.add_argument("--ref-scheme", default="ds", help="scheme of the reference run (default ds)")
    conv.add_argument("--t-end", type=float, help="end of the time window [s]")
    conv.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a config key")
    conv.add_argument("--observables", help="comma-separated observables (default: the scene's)")
    conv.add_argument("--mode", choices=("grouped", "padded", "separate"), default="grouped",
                      help="how the step sizes run: vmap over groups of similar step counts (default), one "
                           "padded vmap, or separate runs (see experiments/benchmarks/bench_batch_h.py)")
    conv.add_argument("--out", type=Path, help="output folder (default: nsga_out/<scene>_convergence)")
    _first_step_limit(conv, "a run or batch of step sizes")

    ident = sub.add_parser("identify", help="fit scene parameters to measured (or synthetic) motion by "
                                            "gradient descent through the simulation", parents=parents)
    ident.add_argument("scene", help="scene name, .toml config or system file")
    ident.add_argument("--params", required=True, help="comma-separated float parameters to identify, e.g. E,e")
    source = ident.add_mutually_exclusive_group(required=True)
    source.add_argument("--data", type=Path, help="measured data: .csv (header t,OBS,...) or .npz (t, OBS...)")
    source.add_argument("--synthetic", action="store_true",
                        help="make the data by simulating the scene with the --true values")
    ident.add_argument("--true", action="append", default=[], metavar="KEY=VALUE",
                       help="true parameter value for --synthetic (repeatable; default: the scene's)")
    ident.add_argument("--initial", action="append", default=[], metavar="KEY=VALUE",
                       help="starting value (repeatable; default: the scene's)")
    ident.add_argument("--observables", help="observables to fit for --synthetic (default: the scene's first)")
    ident.add_argument("--noise", type=float, default=0.0,
                       help="--synthetic: Gaussian noise, as a fraction of each observable's RMS")
    ident.add_argument("--every", type=int, default=1, help="--synthetic: keep every n-th step as a sample")
    ident.add_argument("--seed", type=int, default=0, help="--synthetic: seed of the noise")
    ident.add_argument("--optimizer", choices=("lbfgs", "adam"), default="lbfgs",
                       help="lbfgs (default: L-BFGS with a line search) or adam (first-order, --learning-rate)")
    ident.add_argument("--adjoint", choices=("discrete", "event"), default="discrete",
                       help="the simulated loss's own derivative (default: fewer evaluations for the same "
                            "fits, docs/gradients.md), or gradients that see impact instants move")
    ident.add_argument("--max-steps", type=int, default=100, help="optimiser iterations at most")
    ident.add_argument("--learning-rate", type=float, default=0.05, help="Adam's step (scaled parameters)")
    ident.add_argument("--h", type=float, help="step size [s]")
    ident.add_argument("--t-end", type=float, help="--synthetic: end time [s]")
    ident.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a config key")
    ident.add_argument("--out", type=Path, help="output folder (default: nsga_out/<scene>_identify)")
    _first_step_limit(ident, "a model")

    sw = sub.add_parser("sweep", help="run a scene for every combination of parameter values and step sizes "
                                      "(batched, split over every device, resumable)", parents=parents)
    sw.add_argument("scene", help="scene name, .toml config or system file")
    sw.add_argument("--grid", required=True,
                    help="swept float parameters, e.g. 'e=0:1:11,E=800:1000:5' (start:stop:count) or 'e=0.2;0.5'")
    sw.add_argument("--h", help="comma-separated step sizes [s] (default: the scene's)")
    sw.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="fixed config value for every run (repeatable)")
    sw.add_argument("--batch-size", type=int, help="runs per compiled batch (default: from the model's size)")
    sw.add_argument("--devices", type=int, help="use the first N devices (default: all)")
    sw.add_argument("--max-records", type=int, default=2000,
                    help="recorded steps kept per run for observables and errors (default 2000)")
    sw.add_argument("--out", type=Path, help="output folder (default: nsga_out/<scene>_sweep); "
                                             "run again to resume an interrupted sweep")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")
    _first_step_limit(sw, "a batch")
    hosts = sw.add_argument_group("several processes or hosts (jax.distributed; start the same command in each)")
    hosts.add_argument("--coordinator", metavar="HOST:PORT", help="address where process 0 listens")
    hosts.add_argument("--num-processes", type=int, metavar="N", help="number of processes")
    hosts.add_argument("--process-id", type=int, metavar="I", help="this process's index, in [0, N)")

    bn = sub.add_parser("bench", help="time per step, batched throughput, compile time, float32 vs float64 "
                                      "(default: a quick bench of one scene; --scenes all for every scene)",
                        epilog="The full table of every scene: nsga-jax bench --scenes all --batch 1,64,1024 "
                               "--dtype float64,float32")
    bn.add_argument("--scenes", default=BENCH_SCENES,
                    help="comma-separated scenes: names, .py scene files or system files, or `all` for every "
                         f"built-in scene (default {BENCH_SCENES})")
    bn.add_argument("--batch", default="1,64", help="comma-separated batch sizes (default 1,64)")
    bn.add_argument("--dtype", default="float64",
                    help="comma-separated precisions, float64 and/or float32 (default float64; float64,float32 "
                         "adds float32's time and its distance from float64)")
    bn.add_argument("--scheme", choices=SCHEME_NAMES, default="ds", help="time integration scheme (default ds)")
    bn.add_argument("--repeats", type=int, default=3, help="runs per configuration; the fastest counts")
    bn.add_argument("--max-steps", type=int, default=2000, help="steps per run at most (default 2000)")
    bn.add_argument("--max-seconds", type=float, default=60.0,
                    help="skip a batch whose estimated run time exceeds this (default 60 s)")
    bn.add_argument("--out", type=Path, default=Path("nsga_out/bench"), help="output folder (bench.csv, bench.md)")

    anim = sub.add_parser("animate", help="draw a finished run moving: OUT/animation.gif and a self-contained "
                                          "OUT/animation.html that plays, pauses and scrubs")
    anim.add_argument("folder", type=Path, metavar="OUT", help="the output folder of a finished `nsga-jax run`")
    anim.add_argument("--format", choices=("gif", "html", "both"), default="both", help="what to write (default both)")
    anim.add_argument("--forces", action="store_true", help="draw the contact forces as arrows (normal force, the "
                                                            "largest since the previous frame)")
    anim.add_argument("--fps", type=float, default=20.0, help="frames per second of the playback (default 20, "
                                                              "at most 50)")
    anim.add_argument("--max-frames", type=int, default=120,
                      help="frames at most: a longer run is subsampled evenly (default 120)")

    sub.add_parser("scenes", help="list the built-in scenes and their parameters")
    cfg = sub.add_parser("config", help="print a config to save and edit: a scene's default config, or a "
                                        "config file; --list shows the packaged ones")
    cfg.add_argument("scene", nargs="?",
                     help="a built-in scene name, a system file or a .py scene file (its default config), or a "
                          ".toml config such as configs/rigid_box.toml (printed as it is)")
    cfg.add_argument("--list", action="store_true",
                     help="list the configs, system files and example scenes shipped with the package")
    return p


def package_version() -> str:
    """The installed distribution's version (``importlib.metadata``)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("nsga_jax")
    except PackageNotFoundError:
        return "(not installed: no package metadata found)"


@contextmanager
def one_line_warnings(*reported: type[Warning]) -> Iterator[None]:
    """nsga_jax's own warnings as one ``warning: ...`` line each on stderr
    (once per message), without Python's file and line; the categories in
    ``reported`` not at all (the command prints them itself, from
    ``Solution.warnings``). Other libraries' warnings are shown as usual."""
    shown: set[str] = set()
    with warnings.catch_warnings():
        for category in reported:
            warnings.filterwarnings("ignore", category=category)
        default = warnings.showwarning

        def show(message, category, filename, lineno, file=None, line=None):
            if not category.__module__.startswith("nsga_jax."):
                return default(message, category, filename, lineno, file, line)
            if str(message) not in shown:
                shown.add(str(message))
                print(f"warning: {message}", file=sys.stderr)

        warnings.showwarning = show
        yield


def step_sizes(text: str) -> list[float]:
    """``--h``: comma-separated step sizes (their ranges are the scene's to check)."""
    try:
        return [float(h) for h in text.split(",")]
    except ValueError:
        raise ConfigError(f"--h expects comma-separated numbers, got {text!r}") from None


def option_names(option: str, text: str) -> list[str]:
    """Comma-separated names of an option, at least one."""
    names = [k.strip() for k in text.split(",") if k.strip()]
    if not names:
        raise ConfigError(f"{option} expects comma-separated names, got {text!r}")
    return names


def _first_step_limit(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument("--first-step-limit", type=float, default=60.0, metavar="S",
                        help=f"refuse {what} whose first step is estimated above S seconds (dense iteration "
                             "matrices factorised: n^3 work; default 60); inf runs anyway")
