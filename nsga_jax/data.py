"""Measured observables for identification: times and values, loaded, checked and saved."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from .results import ConfigError


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
            table = np.genfromtxt(path, delimiter=",", names=True)
            names = table.dtype.names
            assert names is not None  # names=True: a structured array
            columns = {k: np.atleast_1d(table[k]) for k in names}
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


__all__ = ["Data"]
