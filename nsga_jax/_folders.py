"""Output folders that cannot mix runs.

A run writes into a folder it has *claimed*: the folder is created (or is
empty, or holds none of a run's files), and ``run.json`` in it names the
invocation. A folder that holds an earlier run's files is refused unless the
caller asks to replace them (``overwrite``: the earlier files are deleted
before anything is written), so that chunks of two runs never end up side by
side. Paths that cannot hold a folder (an existing file, a folder without
write permission) are refused by name before anything is compiled.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from ._results import ConfigError

RUN_FILES = ("run.json", "summary.json", "trajectory.npz", "observables.png", "iterations.png", "partial", "steps",
             "animation.gif", "animation.html")
"""What a run writes into its folder (``run.json`` first, at the claim), and
its animation (``nsga-jax animate``)."""


def writable_folder(path: Path, what: str = "output folder") -> Path:
    """``path`` as a folder this process can write into (created with its
    parents), or :class:`ConfigError` naming why not."""
    path = Path(path).expanduser()
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{what} {str(path)!r} is an existing file, not a folder; choose another path")
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".nsga_jax_write_test_{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as err:
        raise ConfigError(f"{what} {str(path)!r} cannot be written: {err.strerror or err}") from None
    return path


def earlier_run_files(path: Path) -> list[str]:
    """The names of a run's files that ``path`` already holds."""
    return [name for name in RUN_FILES if (path / name).exists()]


def claim_run_folder(path: Path, description: dict, *, overwrite: bool = False) -> Path:
    """Claim ``path`` for one run: refuse it when it holds an earlier run's
    files (unless ``overwrite``, which deletes them first), then write
    ``run.json`` with ``description``, the time of the claim and the folder
    the command ran in (``cwd``: a relative scene path in ``description`` is
    relative to it)."""
    path = writable_folder(path)
    found = earlier_run_files(path)
    if found and not overwrite:
        raise ConfigError(f"output folder {str(path)!r} holds an earlier run ({', '.join(found)}); a run never "
                          "writes beside another run's files: choose another --out, or pass --overwrite to "
                          "replace that run")
    for name in found:
        target = path / name
        shutil.rmtree(target) if target.is_dir() else target.unlink()
    record = {**description, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "pid": os.getpid(), "cwd": os.getcwd()}
    (path / "run.json").write_text(json.dumps(record, indent=2, default=str) + "\n")
    return path


def first_missing(path: Path) -> Path | None:
    """The outermost of ``path`` and its parents that does not exist yet (what
    claiming ``path`` creates), or ``None`` where ``path`` exists."""
    path = Path(path).expanduser().absolute()
    if path.exists():
        return None
    while not path.parent.exists():
        path = path.parent
    return path


def release_run_folder(path: Path, created: Path | None) -> None:
    """Undo the claim of a run that was refused before its first step: delete
    its ``run.json`` and an empty ``partial/``, then ``path`` and its parents
    up to ``created`` (:func:`first_missing` before the claim) where they are
    empty, so that a refused run leaves no folder behind. A folder that existed
    before the claim is kept."""
    path = Path(path).expanduser().absolute()
    (path / "run.json").unlink(missing_ok=True)
    for folder in (path / "partial", path):
        if folder.is_dir() and not any(folder.iterdir()) and (folder != path or created is not None):
            folder.rmdir()
    _remove_empty_parents(path, created)


def _remove_empty_parents(path: Path, created: Path | None) -> None:
    """Delete the empty parents of ``path`` up to ``created`` (which claiming
    ``path`` created); nothing where ``created`` is ``None``."""
    if created is None:
        return
    created = created.absolute()
    while path != created and path.is_relative_to(created) and path.parent.is_dir() \
            and not any(path.parent.iterdir()):
        path = path.parent
        path.rmdir()


@contextmanager
def refusable_folder(path: Path, what: str = "output folder") -> Iterator[Path]:
    """``path`` made writable (:func:`writable_folder`) for a command that may
    still refuse its input (:class:`ConfigError`) before writing anything
    there: on such a refusal the folders this created are deleted again where
    they are empty, so that a refused sweep, study or fit leaves no empty
    folder behind. A folder that existed before is kept."""
    created = first_missing(path)
    path = writable_folder(path, what)
    try:
        yield path
    except ConfigError:
        absolute = path.absolute()
        if created is not None and absolute.is_dir() and not any(absolute.iterdir()):
            absolute.rmdir()
            _remove_empty_parents(absolute, created)
        raise


def free_folder(base: Path) -> Path:
    """``base`` if it holds no earlier run, else the first of ``base_2``,
    ``base_3``, ... that holds none (the default output folder of a run)."""
    base = Path(base)
    candidate, k = base, 1
    while candidate.exists() and (not candidate.is_dir() or earlier_run_files(candidate)):
        k += 1
        candidate = base.with_name(f"{base.name}_{k}")
    return candidate


__all__ = ["RUN_FILES", "claim_run_folder", "earlier_run_files", "first_missing", "free_folder",
           "refusable_folder", "release_run_folder", "writable_folder"]
