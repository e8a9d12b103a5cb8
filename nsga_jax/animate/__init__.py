"""Watching a run move: ``nsga-jax animate OUT`` draws a finished run's
mechanism from its folder, as an animated GIF and a self-contained HTML page."""
