"""The configs and example scenes that ship inside the package.

``nsga_jax/configs/`` holds a documented config of every built-in scene
(``configs/rigid_box.toml``), the extreme cases (``configs/extreme/``) and
the system files (``configs/systems/``); ``nsga_jax/examples/`` holds the
worked example of a user's own model and scene (``examples/double_pendulum.py``
and its config). Wherever a scene or config path is taken (the command
line, :func:`~nsga_jax.load_scene`), a relative path under ``configs/`` or
``examples/`` that does not exist where it is given is read from the
installed package: ``nsga-jax run configs/rigid_box.toml`` runs from any
folder, and a file of that name in the current folder is read instead.
``nsga-jax config --list`` lists them; ``nsga-jax config FILE`` prints one,
to be saved and edited.
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent
"""The folder of the installed package, which holds ``configs/`` and ``examples/``."""

FOLDERS = ("configs", "examples")
"""The packaged folders that relative paths may name."""

SUFFIXES = (".toml", ".py")
"""The kinds of file they hold: configs and system files, and scene files."""


def packaged(path: str | Path) -> Path | None:
    """The packaged file that a relative ``path`` such as
    ``configs/extreme/box_flat.toml`` names, or ``None`` where it names none."""
    parts = Path(path).parts
    if len(parts) < 2 or parts[0] not in FOLDERS or ".." in parts or Path(path).is_absolute():
        return None
    candidate = ROOT.joinpath(*parts)
    return candidate if candidate.is_file() else None


def locate(path: str | Path, relative_to: Path | None = None) -> Path:
    """Where a scene or config ``path`` is read: relative to ``relative_to``
    (a config's folder) when that is given; else as given where it exists;
    else the packaged file it names (:func:`packaged`), if any; else as given,
    for the caller to refuse by name."""
    path = Path(path).expanduser()
    if path.is_absolute():
        return path
    if relative_to is not None:
        return relative_to / path
    if path.exists():
        return path
    return packaged(path) or path


def packaged_files() -> list[str]:
    """Every packaged config, system file and scene file, by the relative
    name that reaches it from any folder (``configs/rigid_box.toml``, ...)."""
    return sorted(p.relative_to(ROOT).as_posix() for folder in FOLDERS for p in (ROOT / folder).rglob("*")
                  if p.is_file() and p.suffix in SUFFIXES)


def first_comment(path: Path, width: int = 100) -> str:
    """What a packaged file is, in a sentence: the first sentence of a
    config's opening comment or of a scene file's docstring, cut to ``width``
    characters."""
    lines: list[str] = []
    for line in path.read_text().splitlines():
        text = line.strip()
        if path.suffix == ".toml" and not text.startswith("#"):
            break
        text = text.lstrip("#").strip().strip('"').strip()
        if not text:
            if lines:
                break
            continue
        lines.append(text)
    sentence = " ".join(lines).split(". ")[0].rstrip(".:;")
    return sentence if len(sentence) <= width else sentence[: width - 3].rstrip() + "..."


__all__ = ["FOLDERS", "ROOT", "first_comment", "locate", "packaged", "packaged_files"]
