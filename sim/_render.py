"""Render what an Xtion on the drone would see of a rubble world, with ground-truth boxes."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from holescan.detect import CameraIntrinsics
from holescan.sim._camera_model import CameraPose, Conditions
from holescan.sim._raster import rasterise_view
from holescan.sim._raycast import cast_rays
from holescan.sim._sensor import colour_image, depth_image
from holescan.sim._world import AccessHole, RubbleWorld
from holescan.sim.registration_bands import Bands
from holescan.sim.structured_light import (
    Motion,
    SensorCamera,
    StructuredLight,
    Surface,
    structured_light_frame,
)

__all__ = ["GtBox", "hole_boxes", "raycast_view", "render", "render_exact"]

F32 = npt.NDArray[np.float32]
F64 = npt.NDArray[np.float64]

_NEAR_M = 0.05


@dataclass(frozen=True)
class GtBox:
    """A hole's opening as seen in one image.

    hole_id : index into :attr:`RubbleWorld.holes`.
    box : (x, y, w, h) pixels, COCO convention (pixel ``i`` spans ``[i, i + 1)``, so the
        image spans ``[0, W] x [0, H]``); clipped to the image.
    iscrowd : the opening is cut by the image border (only part of it is in view).
    """

    hole_id: int
    box: tuple[float, float, float, float]
    iscrowd: bool


def render_exact(
    world: RubbleWorld, pose: CameraPose, camera: CameraIntrinsics, *, surface: bool = False
) -> tuple[F32, F32]:
    """Noise-free view: exact axial depth and linear radiance at every pixel centre.

    Returns
    -------
    depth : (H, W) float32, metres along the optical axis, 0 = no surface (off the field).
    radiance : (H, W, 3) float32, linear RGB radiance (before exposure), 0 = no surface;
        with ``surface``, (H, W, 4): the fourth channel is the surface's infrared unread
        fraction (:attr:`RubbleWorld.ir_unread`).
    """
    p = world.pyramid
    return rasterise_view(
        world.height,
        world.surface if surface else world.radiance,
        world.cell_m,
        p.zmin,
        p.zmax,
        pose.rotation,
        pose.position,
        camera.fx,
        camera.fy,
        camera.cx,
        camera.cy,
        camera.width,
        camera.height,
    )


def raycast_view(world: RubbleWorld, pose: CameraPose, camera: CameraIntrinsics) -> tuple[F32, F32]:
    """Like :func:`render_exact` but by tracing one ray per pixel (slower; a cross-check)."""
    u, v = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    dirs_c = np.stack(
        [(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, np.ones(u.shape)], axis=-1
    ).reshape(-1, 3)
    dirs_c /= np.linalg.norm(dirs_c, axis=1, keepdims=True)
    origins = np.broadcast_to(pose.position, dirs_c.shape)
    t, rad = cast_rays(
        world.height, world.radiance, world.pyramid, world.cell_m, origins, dirs_c @ pose.rotation.T
    )
    depth = np.nan_to_num(t * dirs_c[:, 2], nan=0.0).astype(np.float32)
    shape = (camera.height, camera.width)
    return depth.reshape(shape), rad.reshape(*shape, 3)


def render(
    world: RubbleWorld,
    pose: CameraPose,
    camera: CameraIntrinsics,
    rng: np.random.Generator,
    conditions: Conditions | None = None,
    motion: Motion | None = None,
    bands: Bands | None = None,
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16], tuple[GtBox, ...]]:
    """One registered RGB-D frame as the Xtion would deliver it, and its true access holes.

    Parameters
    ----------
    world : the rubble field.
    pose : camera position (world metres) and rotation (world <- optical frame).
    camera : intrinsics, e.g. ``CameraIntrinsics.xtion()``.
    rng : source of the frame's noise (the same generator state gives the same frame).
    conditions : exposure and sensor artefacts; ``Conditions()`` when None. With
        ``conditions.structured_light`` (the default) the depth goes through the
        structured-light model (:mod:`sim.structured_light`: border bands, projector shadow,
        quantisation, fattening, flying pixels, IR dropouts, misregistration); without it,
        through the basic model of :func:`sim._sensor.depth_image`.
    motion : the camera's image motion during the frame (blur, depth/colour time offset);
        still when None.
    bands : the flight's unread border bands (:func:`sim.registration_bands.draw_bands`,
        once per flight); drawn for this frame alone when None.

    Returns
    -------
    rgb : (H, W, 3) uint8, RGB order.
    depth : (H, W) uint16, millimetres along the optical axis, 0 = no reading.
    boxes : the access holes in view (see :func:`hole_boxes`).
    """
    cond = conditions if conditions is not None else Conditions()
    if not cond.structured_light:
        depth_m, radiance = render_exact(world, pose, camera)
        depth = depth_image(depth_m, camera.fx, cond, rng)
        rgb = colour_image(radiance, camera.cx, camera.cy, cond, rng)
        return rgb, depth, hole_boxes(world, pose, camera)
    depth_m, surf = render_exact(world, pose, camera, surface=True)
    # One SIMD pass for the radiance as its own contiguous array (a strided copy is slower).
    radiance = np.asarray(cv2.cvtColor(surf, cv2.COLOR_RGBA2RGB), np.float32)
    rgb = colour_image(radiance, camera.cx, camera.cy, cond, rng)
    params = StructuredLight(
        min_range_m=cond.min_range_m,
        max_range_m=cond.max_range_m,
        fade_range_m=min(cond.fade_range_m, cond.max_range_m),
    )
    frame = structured_light_frame(
        depth_m,
        rgb,
        SensorCamera(camera.fx, camera.cx, camera.cy),
        seed=rng,
        surface=Surface(ir_unread=surf[..., 3]),
        motion=motion,
        params=params,
        bands=bands,
    )
    assert frame.rgb is not None
    return frame.rgb, frame.depth_mm, hole_boxes(world, pose, camera)


def hole_boxes(
    world: RubbleWorld,
    pose: CameraPose,
    camera: CameraIntrinsics,
    *,
    access_only: bool = True,
) -> tuple[GtBox, ...]:
    """Boxes of the holes' openings (rims) projected into the image.

    The outline at rim height is clipped to the part in front of the camera, projected,
    and clipped to the image. Holes wholly out of view are left out; holes cut by the image
    border get ``iscrowd=True``. Occlusion (rare from above) is ignored.
    ``access_only=False`` also returns the distractors.
    """
    out = []
    for hole in world.holes:
        if access_only and not hole.is_access:
            continue
        box = _opening_box(hole, pose, camera)
        if box is not None:
            out.append(GtBox(hole.id, box[0], box[1]))
    return tuple(out)


def _clip_polygon(poly: F64, keep: npt.NDArray[np.float64], offset: float) -> F64:
    """Sutherland-Hodgman: the part of ``poly`` (N, D) where ``poly @ keep + offset >= 0``."""
    if len(poly) == 0:
        return poly
    s = poly @ keep + offset
    out = []
    n = len(poly)
    for k in range(n):
        a, b = poly[k], poly[(k + 1) % n]
        sa, sb = s[k], s[(k + 1) % n]
        if sa >= 0:
            out.append(a)
        if (sa >= 0) != (sb >= 0):
            out.append(a + (b - a) * (sa / (sa - sb)))
    return np.asarray(out, dtype=np.float64).reshape(-1, poly.shape[1])


def _opening_box(
    hole: AccessHole, pose: CameraPose, camera: CameraIntrinsics
) -> tuple[tuple[float, float, float, float], bool] | None:
    pc = pose.to_camera(hole.opening_xyz())
    if pc[:, 2].max() < _NEAR_M:
        return None
    cut = pc[:, 2].min() < _NEAR_M
    if cut:
        pc = _clip_polygon(pc, np.array([0.0, 0.0, 1.0]), -_NEAR_M)
    # Pixel-edge coordinates (COCO): x = u + 0.5.
    x = camera.fx * pc[:, 0] / pc[:, 2] + camera.cx + 0.5
    y = camera.fy * pc[:, 1] / pc[:, 2] + camera.cy + 0.5
    img = np.column_stack([x, y])
    w, h = float(camera.width), float(camera.height)
    inside = (x >= 0) & (x <= w) & (y >= 0) & (y <= h)
    if not inside.all():
        cut = True
        for keep, off in (((1.0, 0.0), 0.0), ((-1.0, 0.0), w), ((0.0, 1.0), 0.0), ((0.0, -1.0), h)):
            img = _clip_polygon(img, np.asarray(keep), off)
        if len(img) < 3:
            return None
    x0, y0 = img.min(axis=0)
    x1, y1 = img.max(axis=0)
    if x1 - x0 <= 0.0 or y1 - y0 <= 0.0:
        return None
    return (float(x0), float(y0), float(x1 - x0), float(y1 - y0)), cut
