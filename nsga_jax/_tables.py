"""Result tables as CSV files: written whole and atomically, read back typed."""

from __future__ import annotations

import csv
from pathlib import Path


def write_csv(path: str | Path, rows: list[dict]) -> Path:
    """Write ``rows`` (dicts; the columns are their keys, in order of first
    appearance) to a temporary file and move it into place, so that an
    interrupted write never leaves a truncated table."""
    path = Path(path)
    columns: list[str] = []
    for r in rows:
        columns += [c for c in r if c not in columns]
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        w.writerows(rows)
    tmp.replace(path)
    return path


def read_csv(path: str | Path) -> list[dict]:
    """The rows of a table written by :func:`write_csv`, numbers as int or float."""

    def value(text: str):
        try:
            x = float(text)
        except ValueError:
            return text
        return int(x) if x.is_integer() and "." not in text and "e" not in text.lower() else x

    with open(path, newline="") as f:
        return [{k: value(v) for k, v in r.items()} for r in csv.DictReader(f)]
