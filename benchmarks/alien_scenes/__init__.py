"""Alien synthetic rubble scenes: an independent RGB-D generator for robustness tests.

This script writes a COCO-style dataset of Xtion-like RGB-D frames of disaster rubble seen
from 2-3.5 m above at dawn, with labelled access holes. It is written from first principles
and shares no code with ``capture/sim``; it needs only numpy, scipy and OpenCV.

Technique
---------
The scene is a set of analytic solids, ray-cast per pixel with a z-buffer (no height field):

* the base ground is the plane z = 0 of a *site frame* (the pile may slope relative to
  gravity); access holes, small holes and cracks are oblique polygonal shafts cut into it
  (a sheared prism with a floor, or no floor within reach), shallow depressions are
  ellipsoidal bowls;
* rubble is convex polyhedra (random convex hulls and corner-cut boxes for concrete chunks,
  boxes for bricks, blocks, slabs, planks, sheets, octagonal prisms for rebar and poles),
  stacked with a coarse height map, plus ellipsoidal dirt mounds and hollow pipes (tubes);
* each polyhedron is intersected (slab test) with the rays under its projected convex
  hull, in vectorised batches of (pixel, object) pairs, nearest objects first, skipping
  pixels already hidden; the nearest hit wins;
* the same caster renders an orthographic shadow map from the sun, so low dawn sun casts
  long shadows, also into holes.

Photometry: Lambert shading from a warm low sun (absent before sunrise) and a bluish sky with
ambient occlusion (screen space, plus an analytic sky view factor inside shafts), triplanar
FFT-noise textures, dust, dark stains; then a camera model: blur, vignetting, Bayer mosaic,
Poisson shot noise at dawn photon counts, read noise, imperfect auto exposure and white
balance (colour casts), demosaicing, gamma.

Depth: Z along the optical axis with surface roughness, lateral jitter and misregistration,
IR projector shadows (projector 75 mm to the right), axial noise sigma = k 1.425e-6 Z_mm^2 mm
(k = 0.6-1.0, partly spatially correlated), 1/8-pixel disparity quantisation, per-scene
maximum range 3.5-4.5 m, dropouts at grazing angles, on dark or wet surfaces, along depth
edges, in speckles and blobs, and an invalid band at the left border. That is ``--sensor basic``; by
default (``--sensor structured-light``) the depth goes through the project's measured
structured-light model (``holescan.sim.structured_light``): every wet stain and 60 % of
the dry ones (soot, char) swallow 55-76 % of the pattern (listed in the image's
``distractors`` as kind ``stain`` with ``ir_unread``), and the unread border bands are a
recording's: every 10 consecutive frames (``scene.sensor.recording``) share one draw from a
registration profile (``scene.sensor.band_profile``).

Ground truth: each access hole (opening at least 0.7 m x 0.45 m across the shaft axis, at
most 1.6 m, inscribed circle at least 0.42 m) is labelled with the bounding box of its rim
projected into the image (pixel edges: pixel i spans [i, i+1)), and its rim polygon as
``segmentation``. ``iscrowd`` = 1 when the rim is cut by the image border, when less than
half the opening is visible (occluded by rubble), or when the rim lies beyond the sensor's
range; holes with under 5 % of their opening visible, or out of view, are not labelled.

Scene distributions: 0/1/2/3 access holes with probability 0.12/0.45/0.29/0.14 (irregular
polygons, rectangular openings, gaps between two slabs, round shafts and tilted pipes; shaft
axes tilted up to 35 deg; floors 1-2.8 m deep or none within 12 m), 80 % of them placed
wholly in view; Poisson numbers of small holes (< 0.3 m), cracks, small pipes, shallow
bowls (< 0.25 m deep), dark or wet stains; slabs, dirt mounds, walls beyond the view that
cast shadows. Camera 2-3.5 m above the median rubble surface, tilted 0-20 deg from nadir,
any yaw, roll ~1.5 deg; the site slopes 0-10 deg; the sun is 3-28 deg high, or below the
horizon in 25 % of scenes. Intrinsics: fx = fy in 560-580 px, centre within 4 px of the
image centre, one draw per dataset (``camera.json``).

Each image record carries a ``scene`` dict (pose, light, contents) and each annotation
``hole_kind``, ``visible_fraction`` and ``rim_depth_m``, for analysis only. Output is a
deterministic function of (seed, image index), whatever ``--jobs``.

Usage::

    python benchmarks/alien_scenes OUT --n 60 --seed 7 [--jobs 2]
"""

from alien_scenes.cli import main
from alien_scenes.common import CameraModel
from alien_scenes.dataset import generate_dataset

__all__ = ["CameraModel", "generate_dataset", "main"]
