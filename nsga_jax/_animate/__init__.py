"""Watching a run move: ``nsga-jax animate OUT`` draws a finished run's
mechanism from its folder, as an animated GIF and a self-contained HTML page.

::

    from nsga_jax import write_animation

    write_animation("nsga_out/rocking_block", forces=True)   # animation.gif, animation.html

The layers, each usable alone: :func:`load_run` (the folder read back: the
scene rebuilt, the recorded motion), :func:`animation_of` (what is drawn,
frame by frame, derived from the model's structure), :func:`write_gif` and
:func:`write_html` (the two outputs). Importing the package loads no JAX;
drawing a run does.
"""

from .command import write_animation
from .frames import Animation, animation_of
from .gif import write_gif
from .html import write_html
from .run_folder import RecordedRun, load_run

__all__ = ["Animation", "RecordedRun", "animation_of", "load_run", "write_animation", "write_gif", "write_html"]
