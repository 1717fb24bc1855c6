"""Dataset files: write -> read round trip, the synthetic generator, and bad datasets."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from detect import CameraIntrinsics
from ground._datasets import Sample, load_dataset, load_image_pair, write_dataset
from holescan_errors import InputError
from sim._synth import synth_dataset

CAM = CameraIntrinsics.xtion()


def _samples(n: int = 3) -> list[Sample]:
    rng = np.random.default_rng(0)
    out = []
    for i in range(n):
        rgb = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
        depth = rng.integers(0, 5000, (480, 640), dtype=np.uint16)
        boxes = [(10.5 * i, 20.0, 100.0, 80.25)] if i else []
        out.append(Sample(f"img{i}", rgb, depth, boxes, [bool(i == 2)] * len(boxes)))
    return out


def test_round_trip_is_exact(tmp_path: Path) -> None:
    samples = _samples()
    write_dataset(tmp_path / "ds", CAM, samples)
    ds = load_dataset(tmp_path / "ds")
    assert ds.camera == CAM
    assert [im.name for im in ds.images] == ["img0", "img1", "img2"]
    assert ds.n_holes == 1 and ds.n_crowd == 1
    for s, im in zip(samples, ds.images, strict=True):
        rgb, depth = load_image_pair(ds, im)
        assert np.array_equal(rgb, s.rgb) and np.array_equal(depth, s.depth)
        assert im.boxes == tuple(tuple(b) for b in s.boxes)
        assert im.crowd == tuple(s.crowd)
    coco = json.loads((tmp_path / "ds" / "annotations.json").read_text())
    assert coco["categories"] == [{"id": 1, "name": "access_hole"}]
    assert coco["images"][0]["depth_file_name"] == "depth/img0.png"


def test_synthetic_dataset_is_deterministic(tmp_path: Path) -> None:
    a = synth_dataset(tmp_path / "a", 3, seed=5)
    b = synth_dataset(tmp_path / "b", 3, seed=5)
    for name in ("annotations.json", "camera.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes()
    for sub in ("rgb", "depth"):
        for f in sorted((a / sub).iterdir()):
            assert f.read_bytes() == (b / sub / f.name).read_bytes()
    ds = load_dataset(a)
    rgb, depth = load_image_pair(ds, ds.images[0])
    assert rgb.dtype == np.uint8 and depth.dtype == np.uint16 and depth.any()


def test_bad_datasets_are_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such dataset"):
        load_dataset(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match=r"no annotations\.json"):
        load_dataset(tmp_path / "empty")
    write_dataset(tmp_path / "ds", CAM, _samples(2))
    (tmp_path / "ds" / "annotations.json").write_text("{not json")
    with pytest.raises(InputError, match="not readable JSON"):
        load_dataset(tmp_path / "ds")
    write_dataset(tmp_path / "ds2", CAM, _samples(2))
    (tmp_path / "ds2" / "depth" / "img1.png").unlink()
    ds = load_dataset(tmp_path / "ds2")
    with pytest.raises(InputError, match="no such file"):
        load_image_pair(ds, ds.images[1])
    small = CameraIntrinsics.xtion(320, 240)
    (tmp_path / "ds2" / "camera.json").write_text(json.dumps(small.to_dict()))
    with pytest.raises(InputError, match="camera"):
        load_dataset(tmp_path / "ds2")


def test_eight_bit_depth_and_wrong_sized_images_are_refused(tmp_path: Path) -> None:
    import cv2

    write_dataset(tmp_path / "ds", CAM, _samples(2))
    ds = load_dataset(tmp_path / "ds")
    depth_png = ds.images[0].depth_path
    cv2.imwrite(str(depth_png), np.full((480, 640), 200, np.uint8))  # a grey picture, not mm
    with pytest.raises(InputError, match="16-bit"):
        load_image_pair(ds, ds.images[0])
    rgb_png = ds.images[1].rgb_path
    cv2.imwrite(str(rgb_png), np.zeros((240, 320, 3), np.uint8))
    with pytest.raises(InputError, match=r"camera\.json says 640x480"):
        load_image_pair(ds, ds.images[1])
