"""Command-line interface: ``nsga-jax run | scenes | config``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .output import chunk_writer, summary, write_run
from .results import ConfigError, ConvergenceError
from .scenes import REGISTRY, load_scene, parse_override


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="nsga-jax", description=__doc__)
    sub = p.add_subparsers(dest="command", required=True)

    run = sub.add_parser("run", help="simulate a built-in scene or a TOML config")
    run.add_argument("scene", help="scene name (see `nsga-jax scenes`) or path to a .toml config")
    run.add_argument("--h", type=float, help="step size [s]")
    run.add_argument("--t-end", type=float, help="end time [s]")
    run.add_argument("--rho-inf", type=float, help="spectral radius at infinity, in [0, 1]")
    run.add_argument("--scheme", choices=("ds", "dsn", "cs", "mj"), help="time integration scheme")
    run.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                     help="override a config key (repeatable), e.g. --set e=0.5")
    run.add_argument("--no-throw", action="store_true",
                     help="keep going past an unconverged step and mark it in the results")
    run.add_argument("--out", type=Path, help="output folder (default: nsga_out/<scene>)")
    run.add_argument("--chunk", type=int, default=None, help="steps per compiled chunk")
    run.add_argument("--quiet", action="store_true", help="no progress output")

    sub.add_parser("scenes", help="list the built-in scenes and their parameters")
    cfg = sub.add_parser("config", help="print a scene's default TOML config")
    cfg.add_argument("scene")
    return p


def _run(args) -> int:
    overrides = dict(parse_override(s) for s in args.set)
    for key, value in (("h", args.h), ("t_end", args.t_end), ("rho_inf", args.rho_inf), ("scheme", args.scheme)):
        if value is not None:
            overrides[key] = value
    scene = load_scene(args.scene, overrides)
    out = args.out or Path("nsga_out") / scene.name
    if args.chunk is not None and args.chunk < 1:
        raise ConfigError(f"--chunk must be an integer >= 1, got {args.chunk}")
    s = scene.solver
    if not args.quiet:
        print(f"{scene.name}: {s['scheme'].upper()} h = {s['h']:g} s, t_end = {s['t_end']:g} s, "
              f"rho_inf = {s['rho_inf']:g}", file=sys.stderr)
    failure = None
    try:
        sol = scene.run(throw=not args.no_throw, progress=not args.quiet,
                        chunk_size=args.chunk, on_chunk=chunk_writer(out))
    except ConvergenceError as err:
        failure, sol = err, err.solution
    info = summary(sol, scene.name, s["scheme"],
                   {"parameters": scene.parameters, "solver": scene.solver,
                    "error": str(failure) if failure else None})
    paths = write_run(sol, out, info)
    st = sol.stats
    it = st["iterations"]
    print(f"{st['n_steps']} steps in {st['wall_time_s']:.3f} s ({st['us_per_step']:.1f} us/step), "
          f"compile {st['compile_time_s']:.2f} s; Newton iterations mean/max: "
          f"smooth {it['smooth']['mean']:.2f}/{it['smooth']['max']}, "
          f"position {it['position']['mean']:.2f}/{it['position']['max']}, "
          f"velocity {it['velocity']['mean']:.2f}/{it['velocity']['max']}; "
          f"failed steps {st['failed_steps']}; max penetration {st['max_penetration']:.2e} m")
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    if failure is not None:
        print(f"error: {failure}", file=sys.stderr)
        return 1
    return 0


def _scenes() -> int:
    for name, spec in sorted(REGISTRY.items()):
        print(f"{name}: {spec.description}")
        for key, p in spec.parameters.items():
            unit = f" [{p.unit}]" if p.unit else ""
            print(f"    {key} = {p.default!r}{unit}  {p.doc}; {p.range_text()}")
        print(f"    observables: {', '.join(spec.observables)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        if args.command == "run":
            return _run(args)
        if args.command == "scenes":
            return _scenes()
        if args.command == "config":
            if args.scene not in REGISTRY:
                raise ConfigError(f"unknown scene {args.scene!r}; built-in scenes: {', '.join(sorted(REGISTRY))}")
            print(REGISTRY[args.scene].default_toml(), end="")
            return 0
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
