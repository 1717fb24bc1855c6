"""Two rendered rubble frames with their true hole boxes, and recordings made of them."""

from __future__ import annotations

from pathlib import Path

import pytest

from holescan.detect import DEFAULT, CameraIntrinsics, detect_holes
from holescan.ground import load_dataset
from tests.ground.recordings.recwrite import Pair, write_bag, write_tum

Scene = tuple[list[Pair], CameraIntrinsics, list[tuple[tuple[float, float, float, float], ...]]]


@pytest.fixture(scope="session")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Scene:
    """Two frames, each with one access hole wholly in view (the first seed that gives
    that: what a seed renders changes with the sensor model)."""
    from holescan.ground.images import read_depth, read_rgb
    from holescan.sim import synth_dataset

    for seed in range(3, 40):
        ds = load_dataset(synth_dataset(tmp_path_factory.mktemp("synth"), 2, seed=seed))
        if all(len(im.boxes) == 1 and not any(im.crowd) for im in ds.images):
            break
    else:
        raise AssertionError("no seed in 3..39 renders two frames with a whole hole each")
    pairs = [(read_rgb(im.rgb_path), read_depth(im.depth_path)) for im in ds.images]
    return pairs, ds.camera, [im.boxes for im in ds.images]


@pytest.fixture(scope="session")
def scene_candidates(scene: Scene) -> int:
    """How many candidates the default detector gives on the scene's frames as rendered:
    what every recording of them must give too (depth and colour stored losslessly)."""
    pairs, camera, _ = scene
    return sum(len(detect_holes(rgb, mm, camera, DEFAULT)) for rgb, mm in pairs)


@pytest.fixture(scope="session")
def recordings(tmp_path_factory: pytest.TempPathFactory, scene: Scene) -> dict[str, Path]:
    """The scene as a TUM folder, a ROS 1 bag and a ROS 2 bag folder."""
    pairs, camera, _ = scene
    root = tmp_path_factory.mktemp("recordings")
    return {
        "tum": write_tum(root / "rgbd_dataset_scene", pairs),
        "ros1": write_bag(root / "scene.bag", pairs, camera, 1),
        "ros2": write_bag(root / "scene_ros2", pairs, camera, 2, depth_encoding="32FC1"),
    }
