"""A sweep's grid: parsed from text, every combination of its values and step
sizes validated before anything runs, each run's model built when its batch runs."""

from __future__ import annotations

import itertools
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._results import ConfigError
from ._scenes import Configured, Scene, configure


def parse_values(name: str, text: str) -> np.ndarray:
    """``"a:b:n"`` (n values from a to b), ``"a;b;c"`` (a list) or ``"a"``."""
    text = text.strip()
    try:
        if ":" in text:
            parts = text.split(":")
            if len(parts) != 3:
                raise ValueError
            a, b, n = float(parts[0]), float(parts[1]), int(parts[2])
            if n < 1:
                raise ValueError
            return np.linspace(a, b, n)
        return np.asarray([float(x) for x in text.split(";")])
    except ValueError:
        raise ConfigError(f"sweep values of {name!r} must be 'start:stop:count', 'a;b;c' or one number, "
                          f"got {text!r}") from None


def parse_grid(text: str) -> dict[str, np.ndarray]:
    """``"e=0:1:11,E=800:1000:5"`` -> ``{"e": 11 values, "E": 5 values}``."""
    grid: dict[str, np.ndarray] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        if "=" not in item:
            raise ConfigError(f"--grid expects name=values items separated by commas, got {item!r}")
        name, values = (s.strip() for s in item.split("=", 1))
        if name in grid:
            raise ConfigError(f"{name!r} appears twice in the grid")
        grid[name] = parse_values(name, values)
    if not grid:
        raise ConfigError("the grid is empty")
    return grid


MAX_MEMBERS = 1_000_000
"""The most runs one sweep may hold (each is validated before anything runs)."""


@dataclass
class Member:
    """One run of a sweep: its swept values (with h) and its validated
    settings; the scene (its model) is built when its batch runs."""

    index: int
    values: dict[str, float]
    configured: Configured
    _scene: Scene | None = None

    @property
    def scene(self) -> Scene:
        if self._scene is None:
            self._scene = self.configured.build()
        return self._scene


def members(scene: str | Path, grid: dict[str, Sequence[float]] | dict[str, np.ndarray],
            hs: Sequence[float] | np.ndarray | None, overrides: dict[str, Any] | None,
            progress: bool = False) -> list[Member]:
    """Every combination of the grid's values and of the step sizes, each
    validated (bad values raise :class:`ConfigError` before anything is
    compiled; models are built batch by batch)."""
    base = configure(scene, overrides)
    if not isinstance(grid, dict) or not grid:
        raise ConfigError(f"the grid must be a non-empty dict {{parameter: values}}, got {grid!r}")
    grid = {k: np.atleast_1d(np.asarray(v, dtype=float)) for k, v in grid.items()}
    if "h" in grid:
        if hs is not None:
            raise ConfigError("give the step sizes either in the grid or as hs, not both")
        hs = grid.pop("h")
    floats = [k for k, p in base.spec.parameters.items() if p.kind == "float"]
    for k in grid:
        if k not in floats:
            kind = "a structural parameter" if k in base.spec.parameters else "not a parameter"
            raise ConfigError(f"cannot sweep {k!r} of {base.spec.name}: {kind}; sweepable: "
                              f"{', '.join(floats + ['h'])} (set structural parameters with overrides, one sweep "
                              "per value)")
    hs = [base.solver["h"]] if hs is None else [float(h) for h in np.atleast_1d(hs)]
    keys = list(grid)
    total = math.prod(len(grid[k]) for k in keys) * len(hs)
    if total > MAX_MEMBERS:
        sizes = " x ".join(f"{len(grid[k])} {k}" for k in keys) + f" x {len(hs)} h"
        raise ConfigError(f"the sweep has {total:,} runs ({sizes}); at most {MAX_MEMBERS:,} are allowed: "
                          "use fewer values, or several sweeps")
    for k in keys:  # each value against its range once, before the combinations
        for x in np.unique(grid[k]):
            base.spec.parameters[k].check(k, float(x))
    out = []
    shown = time.perf_counter()
    for i, combo in enumerate(itertools.product(*(grid[k] for k in keys), hs)):
        values = {k: float(v) for k, v in zip(keys, combo[:-1])}
        values["h"] = float(combo[-1])
        out.append(Member(i, values, configure(scene, {**(overrides or {}), **values})))
        if progress and time.perf_counter() - shown > 1.0:
            shown = time.perf_counter()
            print(f"\r  validating runs: {i + 1:,}/{total:,}", end="", file=sys.stderr, flush=True)
    return out


__all__ = ["MAX_MEMBERS", "Member", "members", "parse_grid", "parse_values"]
