"""The simulator's synthetic rubble world and its Xtion-like camera (pure numpy/numba).

:func:`make_world` builds a seeded metric height field of rubble (slabs, debris, cracks,
human-size access holes and distractors) with its ground truth; :func:`render` draws one
registered RGB-D frame from any 6-DoF :class:`CameraPose` with the Xtion's artefacts and
returns the access holes' boxes.
"""

from capture.sim._camera_model import CameraPose, Conditions, random_conditions
from capture.sim._render import GtBox, hole_boxes, render, render_exact
from capture.sim._world import AccessHole, HoleKind, RubbleWorld, make_world, relight

__all__ = [
    "AccessHole",
    "CameraPose",
    "Conditions",
    "GtBox",
    "HoleKind",
    "RubbleWorld",
    "hole_boxes",
    "make_world",
    "random_conditions",
    "relight",
    "render",
    "render_exact",
]
