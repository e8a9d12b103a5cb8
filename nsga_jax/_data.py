"""Measured observables for identification: times and values, loaded, checked and saved."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from ._results import ConfigError


@dataclass
class Data:
    """Measured observables: ``t`` (m,) [s] and ``values[name]`` (m,)."""

    t: np.ndarray
    values: dict[str, np.ndarray]

    @classmethod
    def load(cls, path) -> "Data":
        """From an ``.npz`` file (an array ``t`` and one array per observable) or
        a ``.csv`` file (a header line ``t,name,...`` and one row per time)."""
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"data file {str(path)!r} does not exist")
        if path.suffix == ".csv":
            columns = _read_csv(path)
        elif path.suffix == ".npz":
            with np.load(path) as f:
                columns = {k: np.asarray(f[k], float) for k in f.files}
        else:
            raise ConfigError(f"data file {str(path)!r}: expected a .npz or .csv file")
        if "t" not in columns:
            raise ConfigError(f"{path}: the data file needs a column 't' (times [s])")
        data = cls(t=columns.pop("t"), values=columns)
        data.check()
        return data

    def check(self) -> None:
        """Equal lengths, finite values, times >= 0 and increasing."""
        if not self.values:
            raise ConfigError("the data has no observable besides 't'")
        for k, v in {"t": self.t, **self.values}.items():
            if v.shape != self.t.shape or v.ndim != 1:
                raise ConfigError(f"data column {k!r} has shape {v.shape}; expected ({self.t.size},) like 't'")
            if not np.all(np.isfinite(v)):
                raise ConfigError(f"data column {k!r} has non-finite values")
        if self.t[0] < 0 or np.any(np.diff(self.t) <= 0):
            raise ConfigError("data times 't' must be >= 0 and strictly increasing")

    def noise_std(self) -> dict[str, float]:
        """Each observable's measurement noise σ (its standard deviation, in the
        observable's unit), estimated from the data alone.

        The residual of each inner sample from the line through its two
        neighbours, r_i = y_i - (w_- y_{i-1} + w_+ y_{i+1}), has the variance
        σ² (1 + w_-² + w_+²) for white noise, plus a smooth part of order
        Δt² times the second derivative; the median absolute deviation of r
        about its median (x 1.4826, robust to the kinks of impacts) gives σ.
        Data of a smooth noise-free motion give a σ of the order of the change
        of that smooth part between samples."""
        t = self.t
        if t.size < 5:
            return {k: 0.0 for k in self.values}
        dl, dr = t[1:-1] - t[:-2], t[2:] - t[1:-1]
        w_minus, w_plus = dr / (dl + dr), dl / (dl + dr)
        gain = np.sqrt(1.0 + w_minus**2 + w_plus**2)
        out = {}
        for k, y in self.values.items():
            r = (y[1:-1] - (w_minus * y[:-2] + w_plus * y[2:])) / gain
            out[k] = float(1.4826 * np.median(np.abs(r - np.median(r))))
        return out

    def save(self, path) -> Path:
        """As ``.csv`` (header ``t,name,...``) or ``.npz``, by the suffix of ``path``."""
        path = Path(path)
        if path.suffix == ".csv":
            names = ["t", *self.values]
            table = np.column_stack([self.t, *self.values.values()])
            np.savetxt(path, table, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
        else:
            # numpy's stub would let **values fill allow_pickle
            np.savez(path, t=self.t, **cast(dict[str, Any], self.values))
        return path


def _read_csv(path: Path) -> dict[str, np.ndarray]:
    """The columns of a CSV file by its header's names, taken verbatim: an
    observable's dotted name (``lower.theta``) stays as written."""
    with path.open(newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise ConfigError(f"{path}: the data file is empty; expected a header line 't,name,...'")
    names = [name.strip() for name in rows[0]]
    if "" in names or len(set(names)) != len(names):
        raise ConfigError(f"{path}: the header {','.join(names)!r} needs distinct, non-empty column names")
    body = [row for row in rows[1:] if row]
    for k, row in enumerate(body, start=2):
        if len(row) != len(names):
            raise ConfigError(f"{path}, line {k}: {len(row)} values for the {len(names)} columns of the header")
    try:
        table = np.array(body, dtype=float).reshape(len(body), len(names))
    except ValueError as error:
        raise ConfigError(f"{path}: every value must be a number ({error})") from None
    return {name: table[:, i] for i, name in enumerate(names)}


__all__ = ["Data"]
