"""Synthetic evaluation datasets: the simulator's rubble world seen from sampled UAV poses.

Poses are 2-3.5 m above the rubble, mostly nadir (tilt up to 15 deg), any yaw; a third
are centred near a true access hole, a third over a distractor (small hole, crack,
depression, stain, shadow) and a third anywhere, so that most frames hold 0-3 holes and
some distractors. Every frame gets its own exposure, white balance and sensor noise.
Seeded: the same ``(n, seed, worlds)`` always writes the same files.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from holescan.detect import CameraIntrinsics
from holescan.errors import InputError
from holescan.ground import Sample, write_dataset
from holescan.sim._camera_model import CameraPose, random_conditions
from holescan.sim._render import render
from holescan.sim._world import RubbleWorld, make_world
from holescan.sim.registration_bands import draw_bands
from holescan.sim.structured_light import random_motion

log = logging.getLogger(__name__)


def sample_pose(world: RubbleWorld, rng: np.random.Generator) -> CameraPose:
    """A UAV camera pose over ``world``: 2-3.5 m above the rubble, tilt <= 15 deg."""
    sx, sy = world.size_m
    pick = rng.random()
    access = world.access_holes
    others = [h for h in world.holes if not h.is_access]
    if pick < 0.4 and access:
        h = access[int(rng.integers(len(access)))]
        cx, cy = h.centre_xy
        cx, cy = cx + rng.normal(0, 0.5), cy + rng.normal(0, 0.4)
    elif pick < 0.7 and others:
        h = others[int(rng.integers(len(others)))]
        cx, cy = h.centre_xy
    else:
        cx, cy = rng.uniform(2.0, sx - 2.0), rng.uniform(2.0, sy - 2.0)
    cx, cy = float(np.clip(cx, 2.0, sx - 2.0)), float(np.clip(cy, 2.0, sy - 2.0))
    ground = float(
        np.median(
            world.height_at(
                [[cx + dx, cy + dy] for dx in (-1.0, 0.0, 1.0) for dy in (-1.0, 0.0, 1.0)]
            )
        )
    )
    z = ground + float(rng.uniform(2.0, 3.5))
    return CameraPose.looking_down(
        cx,
        cy,
        z,
        yaw=float(rng.uniform(0, 2 * math.pi)),
        tilt=math.radians(float(rng.uniform(0.0, 15.0))),
        tilt_heading=float(rng.uniform(0, 2 * math.pi)),
    )


def synth_samples(
    n: int,
    seed: int,
    camera: CameraIntrinsics,
    images_per_world: int = 20,
    *,
    structured_light: bool = True,
) -> Iterator[Sample]:
    """``n`` rendered frames with their ground-truth boxes (a new world every few frames).

    ``structured_light``: depth through :mod:`sim.structured_light` (the default) with the
    drone's motion (0-1.5 m/s, 5-20 ms exposures) and one recording's border bands per world
    (:mod:`sim.registration_bands`); else the basic depth model, still.
    """
    if n < 1:
        raise InputError(f"--n must be at least 1, got {n}")
    rng = np.random.default_rng(seed)
    world: RubbleWorld | None = None
    bands = None
    for i in range(n):
        if i % images_per_world == 0:
            world = make_world(int(rng.integers(2**31)), (16.0, 16.0))
            # one recording per world: its border bands from a stream of their own
            r_b = np.random.default_rng([seed, i // images_per_world, 0xBA4D])
            bands = draw_bands(r_b, camera.width)
        assert world is not None
        pose = sample_pose(world, rng)
        cond = replace(random_conditions(rng), structured_light=structured_light)
        motion = None
        if structured_light:  # its own stream: the same poses and worlds either way
            r_m = np.random.default_rng([seed, i, 0x30])
            motion = random_motion(r_m, camera.fx, float(pose.position[2] - world.height.mean()))
        rgb, depth, boxes = render(world, pose, camera, rng, cond, motion, bands)
        yield Sample(
            name=f"s{seed}_{i:05d}",
            rgb=rgb,
            depth=depth,
            boxes=[b.box for b in boxes],
            crowd=[bool(b.iscrowd) for b in boxes],
        )


def synth_dataset(
    out: Path,
    n: int,
    seed: int,
    progress: Callable[[int, int], None] | None = None,
    *,
    structured_light: bool = True,
) -> Path:
    """Write ``n`` synthetic frames as a dataset folder at ``out`` (see :func:`synth_samples`)."""
    camera = CameraIntrinsics.xtion()

    def counted() -> Iterator[Sample]:
        samples = synth_samples(n, seed, camera, structured_light=structured_light)
        for i, s in enumerate(samples):
            if progress:
                progress(i + 1, n)
            yield s

    return write_dataset(out, camera, counted())
