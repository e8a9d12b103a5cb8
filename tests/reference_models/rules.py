"""A construction rule of the reference models."""

from __future__ import annotations

import numpy as np


def side_rule(side) -> str | None:
    """``side`` must be exactly +1 or -1 (which side of a wall is admissible):
    any other value scales or removes the gap."""
    values = np.asarray(side)
    if not np.all(np.isin(values, (-1.0, 1.0))):
        return f"side must be +1 or -1 (the admissible side of the wall), got {values.tolist()}"
    return None
