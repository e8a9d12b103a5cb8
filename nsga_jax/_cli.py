"""Command-line interface: ``nsga-jax run | animate | convergence | sweep | bench | identify | scenes | config``."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

from ._animate.command import animate_command, write_animation
from ._cli_config import config_command, scenes_command
from ._cli_options import CACHE_ENV, OneLineErrorParser, command_parser, one_line_warnings, option_names, step_sizes  # noqa: F401  (options)
from ._process_settings import configure_jax
from ._results import ConfigError, ConvergenceError, InvariantError

EXIT_FAILED = 1
"""A run that failed (a step, or a strict invariant) or a fit that did not converge."""
EXIT_INPUT = 2
"""Bad input: the message names the field, the value and what is allowed."""
EXIT_INTERRUPTED = 130
"""Ctrl-C: what was computed is kept on disk, and the message says where."""

BLAS_THREADS = "1"
"""``OPENBLAS_NUM_THREADS`` of the command line (unless the user set it): the
small LAPACK calls of a step gain nothing from OpenBLAS's threads and lose
much when the cores are busy (docs/performance.md, "BLAS threads")."""


def _use_cache(args) -> None:
    """The persistent compilation cache, set up once the command's input is
    validated (it loads JAX)."""
    from ._compilation_cache import default_cache_dir, use_compilation_cache

    use_compilation_cache(None if args.no_cache else default_cache_dir())


def _run(args) -> int:
    from ._first_step import check_limit, check_run_fits
    from ._folders import claim_run_folder, first_missing, free_folder, release_run_folder
    from ._scenes import load_scene, parse_override
    from ._validation import integer

    overrides = dict(parse_override(s) for s in args.set)
    for key, value in (("h", args.h), ("t_end", args.t_end), ("rho_inf", args.rho_inf), ("scheme", args.scheme),
                       ("dtype", args.dtype), ("record_every", args.record_every), ("impact_law", args.impact_law),
                       ("impacts", args.impacts)):
        if value is not None:
            overrides[key] = value
    if args.chunk is not None:
        integer("--chunk", args.chunk, 1)
    check_limit("--first-step-limit", args.first_step_limit)
    scene = load_scene(args.scene, overrides)
    s = scene.solver
    check_run_fits(scene.model, scene.scheme(), {"dtype": s["dtype"], "first_step_limit": args.first_step_limit},
                   what=scene.name, **scene.run_length())  # the memory and first-step refusals before a folder
    out = args.out if args.out is not None else free_folder(Path("nsga_out") / scene.name)
    created = first_missing(out)  # what a run refused later (its records' memory) removes again
    claim_run_folder(out, {"command": "run", "scene": str(args.scene), "parameters": scene.parameters,
                           "solver": scene.solver}, overwrite=args.overwrite)
    _use_cache(args)
    from ._models.redundancy import RedundantConstraintsWarning
    from ._output import summary, write_run
    from ._precision import PrecisionWarning
    from ._saveat import SaveAt
    from ._simulate import InvariantWarning

    if not args.quiet:
        setting = f"theta = {s['theta']:g}" if s["scheme"] == "mj" else f"rho_inf = {s['rho_inf']:g}"
        law = f", impact_law = {s['impact_law']}" if s["impact_law"] != "newton" else ""
        law += ", impacts at their instants" if s["impacts"] == "instants" else ""
        law += ", persistent contacts in the smooth motion" if s.get("persistent_contacts") == "smooth" else ""
        law += ", newton_start = previous" if s.get("newton_start") == "previous" else ""
        print(f"{scene.name}: {s['scheme'].upper()} h = {s['h']:g} s, t_end = {s['t_end']:g} s, "
              f"{setting}, {s['dtype']}{law}; output in {out}", file=sys.stderr)
    failure = None
    saveat = SaveAt(every=s["record_every"], chunks=Path(out) / "partial")  # kept steps on disk as the run goes
    try:
        # printed below, from sol.warnings
        with one_line_warnings(RedundantConstraintsWarning, InvariantWarning, PrecisionWarning):
            sol = scene.run(throw=not args.no_throw, progress=not args.quiet, chunk_size=args.chunk, saveat=saveat,
                            strict=args.strict, first_step_limit=args.first_step_limit)
    except (ConvergenceError, InvariantError) as err:
        assert err.solution is not None  # simulate attaches the run to the errors it raises
        failure, sol = err, err.solution
    except ConfigError:  # refused before its first step: no folder holding only run.json is left
        release_run_folder(out, created)
        raise
    except KeyboardInterrupt:
        from ._chunks import kept_rows

        every = "" if s["record_every"] == 1 else f" (one in every {s['record_every']})"
        print(f"\ninterrupted: the records of {kept_rows(Path(out) / 'partial')} step(s){every} kept in "
              f"{Path(out) / 'partial'} (nsga_jax.load_chunks reads them)", file=sys.stderr)
        return EXIT_INTERRUPTED
    info = summary(sol, scene.name, s["scheme"],
                   {"parameters": scene.parameters, "solver": scene.solver,
                    "error": str(failure) if failure else None})
    paths = write_run(sol, out, info, plots=not args.no_plots)
    if args.animate:
        paths.update(write_animation(out))
    st = sol.stats
    iterations = ", ".join(f"{name} {it['mean']:.2f}/{it['max']}" for name, it in st["iterations"].items()
                           if name != "linear_solves")
    print(f"{st['n_steps']} steps in {st['wall_time_s']:.3f} s ({st['us_per_step']:.1f} us/step), "
          f"compile {st['compile_time_s']:.2f} s ({st['compile_source']}); Newton iterations mean/max: "
          f"{iterations}; "
          f"failed steps {st['failed_steps']}; max penetration {st['max_penetration']:.2e} m; "
          f"bilateral violation {st['max_bilateral_violation_position']:.2e} m"
          + (f"; impacts at their instants {st['impacts_at_instants']} (steps that fell back "
             f"{st['instant_fallbacks']})" if s["impacts"] == "instants" else "")
          + _energy_text(st["energy"]))
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    for warning in st["warnings"]:
        print(f"warning: {warning}", file=sys.stderr)
    if failure is not None:
        print(f"error: {failure}", file=sys.stderr)
        return EXIT_FAILED
    return 0


def _energy_text(energy: dict | None) -> str:
    if energy is None:
        return ""
    rise = energy["max_impact_rise"]
    at_impacts = "" if rise is None else f", largest change over an impact step {rise:+.3g} J"
    return f"; energy {energy['initial']:.6g} -> {energy['final']:.6g} J{at_impacts}"


def _convergence(args) -> int:
    from ._first_step import check_limit
    from ._folders import refusable_folder
    from ._scenes import load_scene, parse_override
    from ._validation import SCHEME_NAMES, real

    overrides = dict(parse_override(s) for s in args.set)
    if args.t_end is not None:
        overrides["t_end"] = args.t_end
    schemes = [s.strip() for s in args.scheme.split(",") if s.strip()]
    if not schemes:
        raise ConfigError(f"--scheme expects comma-separated schemes ({', '.join(SCHEME_NAMES)}), "
                          f"got {args.scheme!r}")
    for s in schemes + [args.ref_scheme]:
        if s not in SCHEME_NAMES:
            raise ConfigError(f"scheme must be one of {', '.join(SCHEME_NAMES)}, got {s!r}")
    hs = step_sizes(args.h)
    if args.ref_h is not None:
        real("--ref-h", args.ref_h, 0.0, lo_open=True, unit="s")
    check_limit("--first-step-limit", args.first_step_limit)
    scene = load_scene(args.scene, overrides)  # validates everything before anything runs
    for h in hs:
        load_scene(args.scene, {**overrides, "h": h})
    observables = (option_names("--observables", args.observables) if args.observables is not None
                   else list(scene.spec.error_observables))
    unknown = [k for k in observables if k not in scene.spec.observables]
    if unknown:
        raise ConfigError(f"unknown observable {unknown[0]!r}; {scene.name} has {', '.join(scene.spec.observables)}")
    with refusable_folder(args.out or Path("nsga_out") / f"{scene.name}_convergence") as out:
        _use_cache(args)
        from ._studies import make_reference, study, write_study

        if args.ref:
            reference = make_reference(args.scene, overrides, "exact", first_step_limit=args.first_step_limit)
        else:
            if args.ref_h >= min(hs):
                raise ConfigError(f"--ref-h must be smaller than every step size, got {args.ref_h} >= {min(hs)}")
            print(f"reference: {args.ref_scheme.upper()} at h = {args.ref_h:g} s ...", file=sys.stderr)
            reference = make_reference(args.scene, {**overrides, "scheme": args.ref_scheme}, args.ref_h,
                                       first_step_limit=args.first_step_limit)
        rows = study(args.scene, schemes, hs, reference, overrides, observables, mode=args.mode,
                     first_step_limit=args.first_step_limit)
        paths = write_study(rows, out, scene.name, reference, plots=not args.no_plots)
        for r in rows:
            errs = ", ".join(f"{k} {e:.3e}" for k, e in r.errors.items())
            it = r.iterations["linear_solves"]
            fail = f", {r.failed_steps} failed steps ({r.result})" if r.failed_steps else ""
            located = (f"; impacts at their instants {r.impacts_at_instants} ({r.instant_fallbacks} steps fell back)"
                       if r.impacts == "instants" else "")
            print(f"{r.scheme:>3} h = {r.h:<8g} {errs}; solves/step {it['mean']:.2f} (max {it['max']}); "
                  f"{r.wall_time_s:.3f} s{fail}{located}")
        print("wrote " + ", ".join(str(p) for p in paths.values()))
        return 0


def _assignments(items: list[str], option: str = "") -> dict:
    """``["a=1,b=2", "c=3"]`` -> ``{"a": 1.0, "b": 2.0, "c": 3.0}``."""
    from ._scenes import parse_override

    parts = [part for item in items for part in item.split(",") if part.strip()]
    if len(parts) < len(items):
        raise ConfigError(f"{option} expects KEY=VALUE, got {items!r}")
    for part in parts:
        if "=" not in part:
            raise ConfigError(f"expected KEY=VALUE, got {part!r}")
    return dict(parse_override(part) for part in parts)


def _identify(args) -> int:
    from ._first_step import check_limit
    from ._folders import refusable_folder
    from ._scenes import load_scene, parse_override
    from ._validation import integer, real

    check_limit("--first-step-limit", args.first_step_limit)
    overrides = dict(parse_override(s) for s in args.set)
    for key, value in (("h", args.h), ("t_end", args.t_end)):
        if value is not None:
            overrides[key] = value
    names = option_names("--params", args.params)
    true: dict[str, Any] | None  # the true values of synthetic data; None for measured data
    true, initial = _assignments(args.true, "--true"), _assignments(args.initial, "--initial")
    for label, values in (("--true", true), ("--initial", initial)):
        extra = [k for k in values if k not in names]
        if extra:
            raise ConfigError(f"{label} sets {extra[0]!r}, which is not in --params ({', '.join(names)})")
    integer("--every", args.every, 1)
    integer("--max-steps", args.max_steps, 1)
    integer("--seed", args.seed, 0)
    real("--learning-rate", args.learning_rate, 0.0, lo_open=True)
    if not (0.0 <= args.noise < 1.0):
        raise ConfigError(f"--noise must be in [0, 1) (a fraction of the RMS), got {args.noise}")
    scene = load_scene(args.scene, {**overrides, **true})  # validates before anything runs
    load_scene(args.scene, {**overrides, **initial})
    floats = [k for k, p in scene.spec.parameters.items() if p.kind == "float"]
    for k in names:
        if k not in floats:
            raise ConfigError(f"--params: {k!r} is not a float parameter of {scene.name}; identifiable: "
                              f"{', '.join(floats)}")
    if args.observables is not None:
        unknown = [k for k in option_names("--observables", args.observables) if k not in scene.spec.observables]
        if unknown:
            raise ConfigError(f"--observables: unknown observable {unknown[0]!r}; {scene.name} has "
                              f"{', '.join(scene.spec.observables)}")
    with refusable_folder(args.out or Path("nsga_out") / f"{scene.name}_identify") as out:
        _use_cache(args)
        from ._adjoint import adjoint_named
        from ._identify import Data, identify, synthetic_data, write_identification

        if args.synthetic:
            observables = (option_names("--observables", args.observables) if args.observables is not None
                           else [scene.spec.observables[0]])
            true = {k: scene.parameters[k] for k in names}
            print(f"synthetic data: {scene.name} with {true}, noise {args.noise:g}", file=sys.stderr)
            data = synthetic_data(args.scene, {**overrides, **true}, observables, noise=args.noise,
                                  seed=args.seed, every=args.every)
            out.mkdir(parents=True, exist_ok=True)
            data.save(out / "data.csv")
        else:
            if args.observables or args.noise or args.every != 1 or args.t_end is not None:
                raise ConfigError("--observables, --noise, --every and --t-end apply to --synthetic only "
                                  "(with --data the file's columns and times are used)")
            data = Data.load(args.data)
            true = None
        print(f"identifying {', '.join(names)} with {args.optimizer} ({args.adjoint} gradients) ...", file=sys.stderr)
        result = identify(args.scene, names, data, overrides=overrides, initial=initial, optimizer=args.optimizer,
                          progress=True, max_steps=args.max_steps, learning_rate=args.learning_rate, true=true,
                          adjoint=adjoint_named(args.adjoint), first_step_limit=args.first_step_limit)
        paths = write_identification(result, data, out, title=f"{scene.name}: {', '.join(names)}", scene=scene,
                                     plots=not args.no_plots)
        for k in names:
            line = f"{k}: initial {result.initial[k]:.6g} -> recovered {result.recovered[k]:.6g}"
            if true is not None:
                line += f" (true {true[k]:.6g}, relative error {result.summary()['relative_error'][k]:.2e})"
            print(line)
        print(f"{result.iterations} iterations, loss {result.losses[0]:.3e} -> {result.losses[-1]:.3e}, "
              f"{result.wall_time_s:.2f} s (compile {result.compile_time_s:.1f} s)")
        print("wrote " + ", ".join(str(p) for p in paths.values()))
        verdict = "converged" if result.converged else "error: the fit did not converge"
        print(f"{verdict}: {result.stop_message}", file=sys.stdout if result.converged else sys.stderr)
        return 0 if result.converged else EXIT_FAILED


def _sweep(args) -> int:
    from contextlib import nullcontext

    from ._first_step import check_limit
    from ._folders import refusable_folder
    from ._scenes import parse_override
    from ._sweep import parse_grid, sweep
    from ._validation import integer

    for name, value, lo in (("--batch-size", args.batch_size, 1), ("--devices", args.devices, 1),
                            ("--max-records", args.max_records, 1)):
        if value is not None:
            integer(name, value, lo)
    check_limit("--first-step-limit", args.first_step_limit)
    grid = parse_grid(args.grid)
    hs = None if args.h is None else step_sizes(args.h)
    _use_cache(args)
    hosts = (args.coordinator, args.num_processes, args.process_id)
    if any(x is not None for x in hosts):
        if any(x is None for x in hosts):
            raise ConfigError("--coordinator, --num-processes and --process-id go together")
        if args.devices is not None:
            raise ConfigError("--devices applies to one process; with several, every process's devices are used")
        from ._distributed import initialize

        initialize(*hosts)  # before anything asks JAX for its devices
    import jax

    devices = jax.devices() if args.devices is None else jax.devices()[: args.devices]
    if args.devices is not None and not 1 <= args.devices <= len(jax.devices()):
        raise ConfigError(f"--devices must be in [1, {len(jax.devices())}], got {args.devices}")
    out = args.out or Path("nsga_out") / f"{Path(args.scene).stem}_sweep"
    folder = refusable_folder(out) if jax.process_index() == 0 else nullcontext()  # process 0 alone writes
    try:
        with folder, one_line_warnings():  # the redundancy report as one line, before the batches run
            result = sweep(args.scene, grid, hs=hs, overrides=dict(parse_override(s) for s in args.set), out=out,
                           batch_size=args.batch_size, devices=devices, max_records=args.max_records,
                           progress=not args.quiet, plots=not args.no_plots,
                           first_step_limit=None if args.first_step_limit == float("inf") else args.first_step_limit)
    except KeyboardInterrupt:
        kept = sorted((Path(out) / "batches").glob("batch_*.csv"))
        print(f"\ninterrupted: {len(kept)} finished batch(es) kept in {Path(out) / 'batches'}; the same command "
              "resumes the sweep from there", file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f"{len(result.rows)} runs on {len(devices)} device(s); compile {result.compile_time:.1f} s, "
          f"runs {result.wall_time:.2f} s (this session's batches)")
    for row in result.failed:
        swept = ", ".join(f"{k}={row[k]:g}" for k in result.swept)
        print(f"warning: run {row['member']} ({swept}) failed at {row['failed_steps']} step(s): {row['result']}",
              file=sys.stderr)
    if result.path is not None:
        print("wrote " + " and ".join(str(p) for p in (result.path, result.plot) if p is not None))
    else:
        print(f"process {jax.process_index()} of {jax.process_count()}: process 0 writes the files")
    return 0


def _bench_scene(text: str) -> str:
    """A ``--scenes`` item: a built-in name, or a scene file (``.py`` or a TOML
    system file) whose scene is registered and named."""
    from ._scenes import REGISTRY, resolve_scene

    if text in REGISTRY or not text.endswith((".py", ".toml")) and ".py:" not in text:
        return text  # bench names the unknown ones with the built-in scenes
    name, config = resolve_scene(text)
    if config is not None:
        raise ConfigError(f"--scenes takes scene names, .py scene files and system files, not the config {text!r}")
    return name


def _bench(args) -> int:
    from ._bench import bench, markdown
    from ._folders import writable_folder
    from ._validation import real

    scenes = None if args.scenes == "all" else [_bench_scene(s.strip()) for s in args.scenes.split(",")]
    try:
        batches = [int(b) for b in args.batch.split(",")]
    except ValueError:
        raise ConfigError(f"--batch expects comma-separated integers, got {args.batch!r}") from None
    real("--max-seconds", args.max_seconds, 0.0, lo_open=True, unit="s")
    writable_folder(args.out)
    rows = bench(scenes, batches, args.dtype.split(","), scheme=args.scheme, repeats=args.repeats,
                 max_steps=args.max_steps, max_seconds=args.max_seconds, out=args.out)
    table = markdown(rows)
    (args.out / "bench.md").write_text(table + "\n")
    print(table)
    print(f"wrote {args.out / 'bench.csv'} and {args.out / 'bench.md'}")
    return 0


COMMANDS = {"run": _run, "animate": animate_command, "convergence": _convergence, "identify": _identify,
            "sweep": _sweep, "bench": _bench, "scenes": scenes_command, "config": config_command}


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code: 0, :data:`EXIT_FAILED`,
    :data:`EXIT_INPUT` (``error: ...`` on one line, no traceback) or
    :data:`EXIT_INTERRUPTED`. Errors inside nsga_jax itself keep their
    traceback."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", BLAS_THREADS)  # effective where numpy is not loaded yet
    configure_jax()  # float64 and XLA's CPU flag for this process (importing nsga_jax sets neither)
    try:
        args = command_parser().parse_args(argv)
        with one_line_warnings():
            return COMMANDS[args.command](args)
    except ConfigError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_INPUT
    except TypeError as err:  # a wrong type reaching the Python API from the command line is bad input too
        if "must be" not in str(err):
            raise
        print(f"error: {err}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print("\ninterrupted (Ctrl-C)", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:  # the output went to a pipe that closed (| head): nothing more to say
        sys.stdout = open(os.devnull, "w")
        return 0


if __name__ == "__main__":
    sys.exit(main())
