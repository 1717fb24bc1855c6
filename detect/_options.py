"""The default detector's design choices as one frozen record (``DetectParams.options``).

Every choice the ablation study (``benchmarks/ablation.py``) undoes one at a time is a field
here, passed down the call: no module state, so two detectors with different options can
run side by side in one process.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["DefaultOptions"]


@dataclass(frozen=True)
class DefaultOptions:
    """Design choices of the default detector (all on in holescan).

    grow_px : grow regions by up to this many work pixels into readings below the opening
        plane (the hole's walls; 0 = the box is the deep region only).
    occluder_step_m : a rim reading this much nearer than the rim's plane is an occluding
        edge, not rim (inf = every reading is rim).
    min_valid_fraction : a work block counts as read when this fraction of its pixels have
        a reading.
    neck_radii_px : radii (work pixels) at which necks between no-reading blobs are cut
        (``()`` = no no-reading blobs; ``(0,)`` = the blobs as they are).
    depression_ratio : a basin this many times larger than its no-reading part is a
        depression holding holes (its unread blobs are candidates of their own).
    dark_split : also measure the dark part of spilled no-reading blobs.
    passable_width : minor axis = min(ellipse axis, largest inscribed disk).
    range_limit_light : at the range limit, darkness is depth evidence.
    photometric_evidence : a region without floor readings counts as a void only as far as
        it is darker than the rubble around it.
    depth_exponent : the depth score's exponent in the combined score
        (:func:`detect._scores.combined_score`).
    cut_circle : an opening cut by the border is placed at the centre of the circle through
        the rim it shows.
    contained : NMS drops a detection when this much of a better one's box lies inside it.
    bands : find the unread bands at the frame border and work on the read area inside.
    closed_border : also look at basins the border cuts as closed there.
    surface_plane : an unread region whose readings well inside its outline lie on its rim
        plane is a surface that returns no infrared (soot, char, wet), not a void: its
        score falls (``detect._surface``).
    trim_spurs : cut thin spurs (a projector shadow's unread line) off candidate regions
        (``detect._regions.trim_spurs``).
    seen_rim_first : in NMS a basin closed across the border cut does not outrank a basin
        inside it whose rim was seen all round, unless that one runs on to the cut.
    pixel_boxes : refine each detection's box at the frame's resolution, to the opening's
        edge in the depth (``detect._boxes.refine_box``); off = the work grid's box.
    dark_box : with ``pixel_boxes``, the box of a region that runs into unread pixels as
        lit as the rubble around them (terrain beyond range, a speckled far field) is its
        dark part's (``detect._boxes._dark_part``).
    """

    grow_px: int = 4
    occluder_step_m: float = 0.25
    min_valid_fraction: float = 0.05
    neck_radii_px: tuple[int, ...] = (0, 3, 6)
    depression_ratio: float = 5.0
    dark_split: bool = True
    passable_width: bool = True
    range_limit_light: bool = True
    photometric_evidence: bool = True
    depth_exponent: float = 0.5
    cut_circle: bool = True
    contained: float = 0.8
    bands: bool = True
    closed_border: bool = True
    surface_plane: bool = True
    trim_spurs: bool = True
    seen_rim_first: bool = True
    pixel_boxes: bool = True
    dark_box: bool = True
