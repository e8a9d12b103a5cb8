"""A finished run read back from its folder: the scene rebuilt from the
run's recorded settings (``run.json``), and the recorded motion
(``trajectory.npz``).

Every refusal is a :class:`~nsga_jax.ConfigError` that names the folder, the
file or field, and what a drawable run needs."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._results import ConfigError

if TYPE_CHECKING:
    from .._system.model import SystemModel

FOLDER_HINT = "give the output folder of a finished `nsga-jax run` (its --out)"


@dataclass(frozen=True)
class RecordedRun:
    """A run's scene and recorded motion.

    Attributes:
        folder: the run's folder.
        name: the scene's name.
        model: the scene's model, rebuilt with the run's parameters.
        times: recorded times (rows,) [s].
        q: recorded coordinates (rows, n) [m, rad].
        impulse: constraint impulses (rows, nc) [N s], bilaterals first.
        gap: unilateral gaps (rows, nu) [m].
        h: the step size [s].
    """

    folder: Path
    name: str
    model: SystemModel
    times: np.ndarray
    q: np.ndarray
    impulse: np.ndarray
    gap: np.ndarray
    h: float


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise ConfigError(f"{path}: cannot be read as JSON ({err})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a JSON object, got {type(data).__name__}")
    return data


def scene_reference(record: dict[str, Any]) -> str:
    """The scene a run named (``run.json``'s ``scene``): a built-in name as
    it is, a relative file path joined to the folder the run was started in
    (``cwd``), so that the run can be drawn from anywhere; a relative path
    not found there, the packaged file it names (``configs/...``)."""
    from .._packaged import packaged
    from .._scenes import REGISTRY

    scene = str(record["scene"])
    cwd = record.get("cwd")
    if scene in REGISTRY or cwd is None:
        return scene
    file, colon, chosen = scene.partition(".py:")
    path = Path(file + ".py" if colon else file).expanduser()
    if not path.is_absolute():
        joined = Path(cwd) / path
        path = joined if joined.exists() else packaged(path) or joined
    return str(path) + (f":{chosen}" if colon else "")


def _settings(folder: Path) -> tuple[str, dict[str, Any], float]:
    """``(scene reference, parameters, h)`` from ``run.json`` (or, for a
    folder written by :func:`~nsga_jax._output.write_run` alone, ``summary.json``)."""
    run, summary = folder / "run.json", folder / "summary.json"
    if run.is_file():
        record = _read_json(run)
        source = run
        if record.get("command") != "run":
            raise ConfigError(f"{run}: command = {record.get('command')!r}; animate draws the folders of "
                              "`nsga-jax run`")
    elif summary.is_file():
        record, source = _read_json(summary), summary
    else:
        raise ConfigError(f"run folder {str(folder)!r} has neither run.json nor summary.json: it does not say "
                          f"which scene ran; {FOLDER_HINT}")
    for key in ("scene", "parameters", "solver"):
        if key not in record:
            raise ConfigError(f"{source}: missing {key!r}; cannot rebuild the run's scene")
    if not isinstance(record["parameters"], dict):
        raise ConfigError(f"{source}: 'parameters' must be an object, got {record['parameters']!r}")
    h = record["solver"].get("h") if isinstance(record["solver"], dict) else None
    if not isinstance(h, (int, float)) or not h > 0:
        raise ConfigError(f"{source}: solver.h must be a positive number [s], got {h!r}")
    return scene_reference(record), record["parameters"], float(h)


def load_run(folder: str | Path) -> RecordedRun:
    """The finished run in ``folder``: its scene rebuilt from the recorded
    scene and parameters, and its recorded times, coordinates, impulses and
    gaps. Loads JAX (to rebuild the model)."""
    folder = Path(folder).expanduser()
    if not folder.exists():
        raise ConfigError(f"run folder {str(folder)!r} does not exist; {FOLDER_HINT}")
    if not folder.is_dir():
        raise ConfigError(f"run folder {str(folder)!r} is a file, not a folder; {FOLDER_HINT}")
    trajectory = folder / "trajectory.npz"
    if not trajectory.is_file():
        partial = " (an unfinished run: partial/ holds its chunks)" if (folder / "partial").exists() else ""
        raise ConfigError(f"run folder {str(folder)!r} holds no finished run: no trajectory.npz{partial}; "
                          f"{FOLDER_HINT}")
    reference, parameters, h = _settings(folder)
    from .._scenes import load_scene
    from .._system.model import SystemModel

    try:
        scene = load_scene(reference, parameters)
    except ConfigError as err:
        raise ConfigError(f"the run's scene {reference!r} cannot be rebuilt: {err}") from None
    if not isinstance(scene.model, SystemModel):
        raise ConfigError(f"scene {scene.name!r}: its model is a {type(scene.model).__name__}, not a system of "
                          "parts (nsga_jax.system.System); animate draws systems: every built-in scene and "
                          "system file")
    try:
        with np.load(trajectory) as data:
            times, q, impulse, gap = (np.asarray(data[k], float) for k in ("t", "q", "impulse", "gap"))
    except (OSError, ValueError, KeyError) as err:
        raise ConfigError(f"{trajectory}: not a run's trajectory ({err})") from None
    model = scene.model
    rows = times.shape[0]
    sizes = {"q": (q, model.n_dof), "impulse": (impulse, model.n_constraints), "gap": (gap, model.n_unilateral)}
    for key, (values, columns) in sizes.items():  # a record of one column may be stored as a vector
        if values.size != rows * columns or (key == "q" and values.shape != (rows, columns)) or rows == 0:
            raise ConfigError(f"{trajectory}: {key} has shape {values.shape}, the scene {scene.name!r} rebuilt from "
                              f"the run's settings has {columns} per record, {rows} records (was its file changed "
                              "since the run?)")
    return RecordedRun(folder, scene.name, model, times, q, impulse.reshape(rows, model.n_constraints),
                       gap.reshape(rows, model.n_unilateral), h)


__all__ = ["RecordedRun", "load_run", "scene_reference"]
