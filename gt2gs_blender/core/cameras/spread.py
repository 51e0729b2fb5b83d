"""Whether views look at a scene from one side (a capture seen from the front, as LLFF's are) or from all
around it: the rule the automatic *Projection* and *Texture Moves Splats* follow. numpy only, so that
Blender's panel can say what they will do without loading torch."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .camera import Camera


def seen_from_front(forwards: np.ndarray, max_deg: float) -> bool:
    """Whether every view direction in ``forwards`` (V, 3) lies within ``max_deg`` of their mean direction;
    directions that cancel out (views all around) say no."""
    forwards = np.asarray(forwards, np.float64).reshape(-1, 3)
    forwards = forwards / np.maximum(np.linalg.norm(forwards, axis=1, keepdims=True), 1e-12)
    mean = forwards.sum(axis=0)
    if len(forwards) == 0 or np.linalg.norm(mean) < 1e-9:
        return False
    spread = forwards @ (mean / np.linalg.norm(mean))
    return float(spread.min()) >= math.cos(math.radians(max_deg))


def cameras_from_front(cameras: Sequence[Camera], max_deg: float) -> bool:
    """:func:`seen_from_front` for the optical axes of ``cameras``."""
    return seen_from_front(np.stack([c.forward for c in cameras]), max_deg)
