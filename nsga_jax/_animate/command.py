"""``nsga-jax animate OUT``: a finished run's folder drawn as
``OUT/animation.gif`` and ``OUT/animation.html``.

Importing this module loads no JAX (the command line answers ``--help`` and
bad options at once); drawing a run does.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .._validation import choice, integer, real
from .frames import DEFAULT_MAX_FRAMES
from .gif import DEFAULT_FPS

FORMATS = ("gif", "html", "both")
"""What ``--format`` writes: the GIF, the HTML page, or both."""

GIF_NAME, HTML_NAME = "animation.gif", "animation.html"
"""The files an animation writes into the run's folder."""

MAX_FPS = 50.0
"""The fastest playback [frames/s]: a GIF frame lasts 20 ms at least."""

MAX_FRAMES_LIMIT = 5000
"""The largest ``--max-frames`` (a page of a few megabytes for a large solid)."""


def check_options(formats: Any, fps: Any, max_frames: Any) -> None:
    """Refuse, by name, an option outside its range (before anything is loaded)."""
    choice("--format", formats, FORMATS)
    real("--fps", fps, 0.0, MAX_FPS, lo_open=True, unit="frames/s")
    integer("--max-frames", max_frames, 1, MAX_FRAMES_LIMIT)


def write_animation(folder: str | Path, *, formats: str = "both", forces: bool = False, fps: float = DEFAULT_FPS,
                    max_frames: int = DEFAULT_MAX_FRAMES) -> dict[str, Path]:
    """Draw the finished run in ``folder`` (:func:`~nsga_jax._animate.run_folder.load_run`)
    and write its animation there: ``animation.gif`` and/or ``animation.html``
    (``formats``), at most ``max_frames`` frames played at ``fps`` frames per
    second, with contact force arrows where ``forces``. Returns the paths written."""
    check_options(formats, fps, max_frames)
    from .._folders import writable_folder
    from .frames import animation_of
    from .gif import write_gif
    from .html import write_html
    from .run_folder import load_run

    run = load_run(folder)
    writable_folder(run.folder, "run folder")
    animation = animation_of(run, max_frames=max_frames, forces=forces)
    paths: dict[str, Path] = {}
    if formats in ("gif", "both"):
        paths["gif"] = write_gif(animation, run.folder / GIF_NAME, fps=fps)
    if formats in ("html", "both"):
        paths["html"] = write_html(animation, run.folder / HTML_NAME, fps=fps)
    return paths


def animate_command(args: Any) -> int:
    """The command: write the animation, then say what was written."""
    paths = write_animation(args.folder, formats=args.format, forces=args.forces, fps=args.fps,
                            max_frames=args.max_frames)
    print("wrote " + ", ".join(str(p) for p in paths.values()))
    return 0


__all__ = ["FORMATS", "GIF_NAME", "HTML_NAME", "animate_command", "check_options", "write_animation"]
