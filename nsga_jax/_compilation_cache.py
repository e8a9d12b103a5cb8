"""A persistent compilation cache: compiled programs kept on disk between runs.

A run's programs depend on the model's structure, the scheme and the
precision, never on h or on parameter values (they are traced). The first run
of a structure compiles them (seconds, see docs/performance.md); with
the cache on, every later run of that structure, in any process, loads them
from disk instead. This is JAX's own persistent cache
(``jax_compilation_cache_dir``), pointed at a folder of ours. A scene's
programs take a few MB; the folder is never pruned (delete it at will).

The command line turns it on for run, convergence, identify and sweep
(`--no-cache` turns it off there); the folder is
``$NSGA_JAX_CACHE`` if set (``off`` turns the cache off), else
``$XDG_CACHE_HOME/nsga_jax/xla`` (``~/.cache/nsga_jax/xla``). In Python, call
:func:`use_compilation_cache`. The folder holds compiled machine code: keep it
private (JAX trusts what it loads from there).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import jax

from ._compat import jax_option, reset_compilation_cache

ENV = "NSGA_JAX_CACHE"
OFF = ("off", "0", "no", "false", "none")
MIN_COMPILE_SECONDS = 0.2
"""Programs that compile faster than this are not written (small helpers)."""


def default_cache_dir() -> Path | None:
    """The folder the command line uses: ``$NSGA_JAX_CACHE``, ``None`` when that
    says ``off``, else ``$XDG_CACHE_HOME/nsga_jax/xla``."""
    value = os.environ.get(ENV)
    if value is not None:
        return None if value.strip().lower() in OFF or not value.strip() else Path(value).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "nsga_jax" / "xla"


def use_compilation_cache(path: str | Path | None) -> Path | None:
    """Keep compiled programs in ``path`` (created if missing) from now on, and
    load them from there; ``None`` turns the persistent cache off. Returns the
    folder in use."""
    if path is not None:
        path = Path(path).expanduser().resolve()
        path.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
        jax.config.update("jax_enable_compilation_cache", True)
    jax.config.update("jax_compilation_cache_dir", None if path is None else str(path))
    reset_compilation_cache()
    return path


def current_cache_dir() -> Path | None:
    """The folder of the persistent cache in use, or ``None``."""
    path = jax_option("jax_compilation_cache_dir")
    return Path(path) if path and jax_option("jax_enable_compilation_cache") else None


@contextlib.contextmanager
def cache_events() -> Iterator[dict[str, int]]:
    """Count the persistent cache's hits and misses of the compilations inside
    the block (``{"hits": h, "misses": m}``, JAX's own monitoring events), so
    that a run can say whether its programs were compiled or loaded."""
    counts = {"hits": 0, "misses": 0}

    def listener(event: str, **kwargs) -> None:
        if event == "/jax/compilation_cache/cache_hits":
            counts["hits"] += 1
        elif event == "/jax/compilation_cache/cache_misses":
            counts["misses"] += 1

    jax.monitoring.register_event_listener(listener)
    try:
        yield counts
    finally:
        jax.monitoring.unregister_event_listener(listener)


def compile_source(counts: dict[str, int]) -> str:
    """How a run's programs were obtained, from :func:`cache_events`' counts."""
    if counts["hits"] and not counts["misses"]:
        return "loaded from the persistent cache"
    if counts["hits"]:
        return "partly loaded from the persistent cache"
    return "compiled"


@contextlib.contextmanager
def compilation_cache(path: str | Path | None) -> Iterator[Path | None]:
    """Use the persistent cache at ``path`` (``None``: none) inside the block,
    and the previous setting after it."""
    previous = current_cache_dir()
    try:
        yield use_compilation_cache(path)
    finally:
        use_compilation_cache(previous)
