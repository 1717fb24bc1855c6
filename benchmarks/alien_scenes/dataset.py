"""Alien scenes: ground truth and the dataset writer."""

from __future__ import annotations

import concurrent.futures
import json
import multiprocessing
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alien_scenes.common import F64, CameraModel, Textures, make_textures
from alien_scenes.raycast import PerspectiveView
from alien_scenes.sampling import polygon_area
from alien_scenes.scene import sample_scene
from alien_scenes.shading import (
    Surface,
    depth_sensor,
    rgb_sensor,
    shade,
    structured_light_sensor,
)
from alien_scenes.shapes import Scene, Shape, make_library

# --------------------------------------------------------------------------- ground truth


def _clip_polygon(p: F64, x0: float, y0: float, x1: float, y1: float) -> F64:
    """Sutherland-Hodgman clip of polygon (N, 2) to a rectangle."""
    for axis, val, ge in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        if len(p) == 0:
            break
        out = []
        for i in range(len(p)):
            a, b = p[i - 1], p[i]
            ina = a[axis] >= val if ge else a[axis] <= val
            inb = b[axis] >= val if ge else b[axis] <= val
            if ina != inb:
                f = (val - a[axis]) / (b[axis] - a[axis])
                out.append(a + f * (b - a))
            if inb:
                out.append(b)
        p = np.array(out).reshape(-1, 2)
    return p


def _annotate(sc: Scene, cam: CameraModel, s: Surface) -> list[dict[str, Any]]:
    """COCO annotations (without ids) of the access holes in view."""
    anns = []
    for hole in sc.holes:
        if not hole.access:
            continue
        X = (hole.rim - sc.C) @ sc.R
        if (X[:, 2] <= 0.05).any():
            continue
        uv = np.column_stack(
            [cam.fx * X[:, 0] / X[:, 2] + cam.cx + 0.5, cam.fy * X[:, 1] / X[:, 2] + cam.cy + 0.5]
        )
        clipped = _clip_polygon(uv, 0, 0, cam.width, cam.height)
        if len(clipped) < 3 or polygon_area(clipped) < 4:
            continue
        m = np.zeros((cam.height, cam.width), np.uint8)
        cv2.fillPoly(m, [np.round((clipped - 0.5) * 16).astype(np.int32)], 1, cv2.LINE_8, 4)
        npx = int(m.sum())
        if npx == 0:
            continue
        vis = float(((s.tag == hole.tag) & (m > 0)).sum()) / npx
        if vis < 0.05:
            continue
        cut = bool(((uv < 0) | (uv > [cam.width, cam.height])).any())
        far = float(np.median(X[:, 2])) > sc.zmax
        lo, hi = clipped.min(0), clipped.max(0)
        anns.append(
            {
                "category_id": 1,
                "bbox": [round(float(v), 2) + 0.0 for v in (*lo, *(hi - lo))],  # no -0.0
                "area": round(polygon_area(clipped), 2),
                "segmentation": [[round(float(v), 2) for v in clipped.ravel()]],
                "iscrowd": int(cut or vis < 0.5 or far),
                "hole_kind": hole.kind,
                "visible_fraction": round(vis, 3),
                "rim_depth_m": round(float(np.median(X[:, 2])), 3),
            }
        )
    return anns


def _stains(sc: Scene, s: Surface, absorbing: dict[int, float]) -> list[dict[str, Any]]:
    """Distractor records of the stains in view (their cores, at least ``_MIN_STAIN_PX``):
    box (pixel i spans [i, i+1)), wet or not, and the fraction of the pattern an absorbing
    one swallows (``ir_unread``)."""
    out = []
    for k, st in enumerate(sc.stains):
        ys, xs = np.nonzero(s.stain == k + 1)
        if ys.size < _MIN_STAIN_PX:
            continue
        x0, y0 = int(xs.min()), int(ys.min())
        e: dict[str, Any] = {
            "kind": "stain",
            "feature_id": k + 1,
            "bbox": [x0, y0, int(xs.max()) + 1 - x0, int(ys.max()) + 1 - y0],
            "pixels": int(ys.size),
            "wet": bool(st.wet),
        }
        if k + 1 in absorbing:
            e["ir_unread"] = absorbing[k + 1]
        out.append(e)
    return out


# --------------------------------------------------------------------------- dataset

#: Frames per recording: consecutive frames share their border bands (one registration).
RECORDING_FRAMES = 10
_MIN_STAIN_PX = 60


@dataclass(frozen=True)
class _Job:
    index: int
    seed: int
    cam: CameraModel
    out: Path
    sensor: str = "structured-light"


def _assets(seed: int) -> tuple[list[Shape], Textures]:
    rng = np.random.default_rng([seed, 0xA11E])
    return make_library(rng), make_textures(rng)


def _render_image(
    job: _Job, lib: list[Shape], tex: Textures
) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    rng = np.random.default_rng([job.seed, job.index, 1])
    sc = sample_scene(rng, job.cam, lib)
    view = PerspectiveView(job.cam, sc.C, sc.R)
    surf = shade(rng, sc, view, tex)
    rgb = rgb_sensor(rng, sc, surf.radiance)
    if job.sensor == "structured-light":
        from holescan.sim.registration_bands import draw_bands  # the project's sensor model

        rng_sl = np.random.default_rng([job.seed, job.index, 2])
        # the border bands are the recording's registration: one draw per RECORDING_FRAMES
        recording = job.index // RECORDING_FRAMES
        bands = draw_bands(np.random.default_rng([job.seed, recording, 0xBA4D]), job.cam.width)
        depth, rgb, sensor = structured_light_sensor(rng_sl, sc, job.cam, surf, rgb, bands)
        sensor["recording"] = recording
    else:
        depth, sensor = depth_sensor(rng, sc, job.cam, surf), {}
    anns = _annotate(sc, job.cam, surf)
    distractors = _stains(sc, surf, sensor.get("absorbing_stains", {}))
    name = f"alien_{job.index:05d}.png"
    if not cv2.imwrite(str(job.out / "rgb" / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
        raise OSError(f"cannot write {job.out / 'rgb' / name}")
    if not cv2.imwrite(str(job.out / "depth" / name), depth):
        raise OSError(f"cannot write {job.out / 'depth' / name}")
    image = {
        "id": job.index + 1,
        "file_name": f"rgb/{name}",
        "depth_file_name": f"depth/{name}",
        "width": job.cam.width,
        "height": job.cam.height,
        "scene": sc.meta
        | {
            "max_range_m": round(sc.zmax, 3),
            "valid_depth_fraction": round(float((depth > 0).mean()), 3),
            "sensor_model": job.sensor,
            "sensor": sensor,
        },
        "distractors": distractors,
    }
    return image, anns


_WORKER_ASSETS: dict[int, tuple[list[Shape], Textures]] = {}


def _worker(job: _Job) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    if job.seed not in _WORKER_ASSETS:
        _WORKER_ASSETS[job.seed] = _assets(job.seed)
    lib, tex = _WORKER_ASSETS[job.seed]
    return _render_image(job, lib, tex)


def generate_dataset(
    out: Path, n: int, seed: int, jobs: int = 1, sensor: str = "structured-light"
) -> dict[str, Any]:
    """Write ``n`` scenes to ``out`` (annotations.json, camera.json, rgb/, depth/).

    Deterministic for (n, seed) whatever ``jobs`` is. Returns a summary: images, holes,
    crowd, empty images, seconds.
    """
    if n < 1:
        raise ValueError("n must be >= 1")
    t0 = time.monotonic()
    out = Path(out)
    (out / "rgb").mkdir(parents=True, exist_ok=True)
    (out / "depth").mkdir(parents=True, exist_ok=True)
    cam = CameraModel.sample(np.random.default_rng([seed, 0xCA]))
    work = [_Job(i, seed, cam, out, sensor) for i in range(n)]
    if jobs > 1:
        # spawn, not fork: a forked worker inherits the parent's threads' locks (OpenCV's
        # pool, a test runner's); and an executor, not a Pool: a worker that dies raises
        # BrokenProcessPool here instead of leaving Pool.map waiting forever
        ctx = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(jobs, mp_context=ctx) as pool:
            results = list(pool.map(_worker, work))
    else:
        results = [_worker(j) for j in work]
    images: list[dict[str, Any]] = []
    annotations: list[dict[str, Any]] = []
    for image, anns in results:
        images.append(image)
        for a in anns:
            annotations.append({"id": len(annotations) + 1, "image_id": image["id"]} | a)
    coco = {
        "info": {
            "description": "alien synthetic rubble scenes (benchmarks/alien_scenes.py)",
            "seed": seed,
            "version": "1",
            "sensor": sensor,
        },
        "images": images,
        "annotations": annotations,
        "categories": [{"id": 1, "name": "access_hole", "supercategory": "hole"}],
    }
    (out / "annotations.json").write_text(json.dumps(coco, indent=1))
    (out / "camera.json").write_text(json.dumps(cam.to_json(), indent=1))
    crowd = sum(a["iscrowd"] for a in annotations)
    with_hole = {a["image_id"] for a in annotations if not a["iscrowd"]}
    return {
        "images": n,
        "holes": len(annotations) - crowd,
        "crowd": crowd,
        "images_without_hole": n - len(with_hole),
        "seconds": round(time.monotonic() - t0, 1),
    }
