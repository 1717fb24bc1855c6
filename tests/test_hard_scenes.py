"""benchmarks/hard_scenes: the held-out scene generator writes a loadable, deterministic
dataset whose truth covers every distractor kind."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
import pytest

PKG = Path(__file__).resolve().parents[1] / "benchmarks" / "hard_scenes"


def _generate(out: Path, jobs: int, n: int = 3, seed: int = 7) -> Path:
    cmd = [
        sys.executable,
        str(PKG),
        str(out),
        "--n",
        str(n),
        "--seed",
        str(seed),
        "--jobs",
        str(jobs),
        "--scale",
        "0.4",
    ]
    subprocess.run(cmd, check=True, capture_output=True, text=True, timeout=120)
    return out


@pytest.fixture(scope="module")
def datasets(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("hard")
    return _generate(root / "one", jobs=1), _generate(root / "two", jobs=2)


def test_layout_loads_and_is_sane(datasets: tuple[Path, Path]) -> None:
    ds = datasets[0]
    coco = json.loads((ds / "annotations.json").read_text())
    cam = json.loads((ds / "camera.json").read_text())
    assert cam["width"] == 256 and cam["height"] == 192 and cam["depth_unit_m"] == 0.001
    assert 227 < cam["fx"] < 231 and cam["fx"] == cam["fy"]
    assert coco["categories"] == [{"id": 1, "name": "access_hole"}]
    assert len(coco["images"]) == 3
    from holescan.ground import load_dataset

    loaded = load_dataset(ds)
    assert len(loaded.images) == 3
    assert loaded.n_holes + loaded.n_crowd == len(coco["annotations"])
    for im in coco["images"]:
        assert im["file_name"].startswith("rgb/") and im["depth_file_name"].startswith("depth/")
        rgb = cv2.imread(str(ds / im["file_name"]), cv2.IMREAD_UNCHANGED)
        depth = cv2.imread(str(ds / im["depth_file_name"]), cv2.IMREAD_UNCHANGED)
        assert rgb.dtype == np.uint8 and rgb.shape == (192, 256, 3)
        assert depth.dtype == np.uint16 and depth.shape == (192, 256)
        valid = depth[depth > 0]
        assert valid.size > 0.3 * depth.size and valid.min() >= 500 and valid.max() <= 4600
        assert "scene" in im and isinstance(im["distractors"], list)
        for d in im["distractors"]:
            _inside(d["bbox"], 256, 192)
    for a in coco["annotations"]:
        _inside(a["bbox"], 256, 192)
        assert a["category_id"] == 1 and a["iscrowd"] in (0, 1)
        assert a["kind"] in ("hole_void", "hole_floor")
        assert a["area"] == pytest.approx(a["bbox"][2] * a["bbox"][3])


def _inside(box: list[float], w: int, h: int) -> None:
    x, y, bw, bh = box
    assert x >= 0 and y >= 0 and bw > 0 and bh > 0 and x + bw <= w and y + bh <= h


def test_output_does_not_depend_on_jobs(datasets: tuple[Path, Path]) -> None:
    one, two = datasets
    files = sorted(p.relative_to(one) for p in one.rglob("*") if p.is_file())
    assert len(files) == 2 + 2 * 3
    for f in files:
        assert (one / f).read_bytes() == (two / f).read_bytes(), f


def test_every_distractor_kind_is_planned_across_a_seeded_set() -> None:
    sys.path.insert(0, str(PKG))
    try:
        from camera import dataset_intrinsics
        from plan import DISTRACTORS, sample_plan
    finally:
        sys.path.remove(str(PKG))
    intr = dataset_intrinsics(3)
    kinds: Counter[str] = Counter()
    for i in range(40):
        rng = np.random.default_rng(np.random.SeedSequence([3, i]).spawn(4)[0])
        plan = sample_plan(rng, intr)
        for f in plan.features:
            kinds[f["kind"]] += 1
            if f["kind"] == "hole":
                kinds["hole/" + f["placement"]] += 1
                kinds["hole/" + f["floor"]] += 1
                kinds["hole/occluded"] += bool(f["occluder"])
    for k in (
        *DISTRACTORS,
        "hole/border",
        "hole/range_limit",
        "hole/occluded",
        "hole/void",
        "hole/debris",
    ):
        assert kinds[k] >= 1, (k, kinds)


def test_sensor_model() -> None:
    sys.path.insert(0, str(PKG))
    try:
        from camera import dataset_intrinsics
        from sensor import xtion_depth
    finally:
        sys.path.remove(str(PKG))
    intr = dataset_intrinsics(0)
    Z = np.full((480, 640), 3.0)
    Z[:, 600:] = 5.0  # beyond the range cut-off
    no_ret = np.zeros(Z.shape, bool)
    no_ret[100:200, 100:200] = True
    depth, _ = xtion_depth(np.random.default_rng(0), intr, Z, no_ret, np.ones(Z.shape), 4.0)
    assert depth.dtype == np.uint16
    assert not depth[:, 600:].any()
    assert np.mean(depth[100:200, 100:200] > 0) < 0.1
    flat = depth[250:450, 50:550].astype(float)
    flat = flat[flat > 0]
    assert abs(np.median(flat) - 3000) < 20 and 8 < np.std(flat) < 25  # sigma 12.8 mm at 3 m


def test_a_recordings_frames_share_their_border_bands(datasets: tuple[Path, Path]) -> None:
    coco = json.loads((datasets[0] / "annotations.json").read_text())
    sensors = [im["scene"]["sensor"] for im in coco["images"]]
    assert {s["recording"] for s in sensors} == {0}  # the first 10 frames: one recording
    assert len({(tuple(s["bands_ltrb_px"]), s["band_profile"]) for s in sensors}) == 1
    for im in coco["images"]:
        depth = cv2.imread(str(datasets[0] / im["depth_file_name"]), cv2.IMREAD_UNCHANGED)
        left, top, right, bottom = im["scene"]["sensor"]["bands_ltrb_px"]
        assert not depth[:, :left].any() and not depth[:, 256 - right :].any()
        assert not depth[:top].any() and not depth[192 - bottom :].any()
