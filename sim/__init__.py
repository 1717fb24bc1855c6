"""The simulated world, Xtion and autopilot: everything the flight side can be tested against.

Beside the flight side, never imported by it: it may import :mod:`capture`,
:mod:`missions` and :mod:`ground`. The demo application (``holescan demo``) is
:mod:`holescan.demo`, above it.

* :func:`make_world` builds a seeded metric height field of rubble (slabs, debris, cracks,
  human-size access holes and distractors) with its ground truth; :func:`render` draws one
  registered RGB-D frame from any 6-DoF :class:`CameraPose` with the Xtion's artefacts and
  returns the access holes' boxes (pure numpy/numba).
* :class:`SimAutopilot` - a MAVLink autopilot over loopback flying a :class:`SimPath`.
* :class:`SimSource` - the simulated Xtion as a :class:`detect.FrameSource`.
* :class:`SimSortie` - world + autopilot + camera for one survey; :func:`fly_sim` flies it
  through :func:`capture.fly` (``holescan fly --sensor sim``).
* :func:`synth_dataset` - a synthetic annotated RGB-D dataset.
"""

from holescan.sim._autopilot import SimAutopilot
from holescan.sim._camera_model import CameraPose, Conditions, random_conditions
from holescan.sim._fly import (
    SIM_TABLE,
    SimFlyReport,
    check_sim,
    fly_sim,
    format_sim_report,
    sortie_params,
)
from holescan.sim._lap import LapReplay, prerender_lap
from holescan.sim._render import GtBox, hole_boxes, render, render_exact
from holescan.sim._reported import ReportedPoseCamera, anchor_at_home
from holescan.sim._sortie import (
    DEFAULT_ANCHOR,
    SimSortie,
    SortieParams,
    TrueHole,
    lap_frames,
    loop_length_m,
    make_sortie_world,
    survey_path,
    true_holes,
    world_area,
)
from holescan.sim._source import SimSource, WorldAnchor, camera_pose_in_world, image_motion
from holescan.sim._synth import sample_pose, synth_dataset, synth_samples
from holescan.sim._trajectory import SimPath
from holescan.sim._world import AccessHole, HoleKind, RubbleWorld, make_world, relight

__all__ = [
    "DEFAULT_ANCHOR",
    "SIM_TABLE",
    "AccessHole",
    "CameraPose",
    "Conditions",
    "GtBox",
    "HoleKind",
    "LapReplay",
    "ReportedPoseCamera",
    "RubbleWorld",
    "SimAutopilot",
    "SimFlyReport",
    "SimPath",
    "SimSortie",
    "SimSource",
    "SortieParams",
    "TrueHole",
    "WorldAnchor",
    "anchor_at_home",
    "camera_pose_in_world",
    "check_sim",
    "fly_sim",
    "format_sim_report",
    "hole_boxes",
    "image_motion",
    "lap_frames",
    "loop_length_m",
    "make_sortie_world",
    "make_world",
    "prerender_lap",
    "random_conditions",
    "relight",
    "render",
    "render_exact",
    "sample_pose",
    "sortie_params",
    "survey_path",
    "synth_dataset",
    "synth_samples",
    "true_holes",
    "world_area",
]
