"""Smoke tests of the independent ("alien") synthetic rubble scene generator."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import cv2
import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "alien_scenes"


@pytest.fixture(scope="module")
def alien() -> ModuleType:
    sys.path.insert(0, str(SCRIPT.parent))  # the package lives in benchmarks/, run as a folder
    try:
        parts = (
            "alien_scenes",
            "alien_scenes.dataset",
            "alien_scenes.scene",
            "alien_scenes.raycast",
        )
        parts += ("alien_scenes.shading",)
        names: dict[str, object] = {}
        for name in parts:
            names.update(vars(importlib.import_module(name)))
        ns = ModuleType("alien_scenes_all", "the generator's modules' names in one namespace")
        ns.__dict__.update({k: v for k, v in names.items() if not k.startswith("__")})
        return ns
    finally:
        sys.path.remove(str(SCRIPT.parent))


@pytest.fixture(scope="module")
def dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("alien") / "ds"
    run = subprocess.run(
        [sys.executable, str(SCRIPT), str(out), "--n", "3", "--seed", "11"],
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    assert "images 3" in run.stdout
    return out


def test_cli_writes_a_valid_coco_dataset(dataset: Path) -> None:
    coco = json.loads((dataset / "annotations.json").read_text())
    camera = json.loads((dataset / "camera.json").read_text())
    assert set(camera) == {"width", "height", "fx", "fy", "cx", "cy", "depth_unit_m"}
    assert camera["depth_unit_m"] == 0.001
    assert 560 <= camera["fx"] == camera["fy"] <= 580
    assert abs(camera["cx"] - 319.5) < 5
    assert abs(camera["cy"] - 239.5) < 5
    assert coco["categories"] == [{"id": 1, "name": "access_hole", "supercategory": "hole"}]
    assert [im["id"] for im in coco["images"]] == [1, 2, 3]
    for im in coco["images"]:
        rgb = cv2.imread(str(dataset / im["file_name"]), cv2.IMREAD_UNCHANGED)
        depth = cv2.imread(str(dataset / im["depth_file_name"]), cv2.IMREAD_UNCHANGED)
        assert rgb.shape == (480, 640, 3)
        assert rgb.dtype == np.uint8
        assert depth.shape == (480, 640)
        assert depth.dtype == np.uint16
        assert (im["width"], im["height"]) == (640, 480)
        valid = depth[depth > 0]
        assert 0.3 < valid.size / depth.size < 0.99  # dropouts, but mostly readings
        assert valid.min() >= 500
        assert valid.max() <= 4500
        assert 20 < rgb.mean() < 200
        assert rgb.std() > 10
    ids = [a["id"] for a in coco["annotations"]]
    assert ids == list(range(1, len(ids) + 1))
    for a in coco["annotations"]:
        x, y, w, h = a["bbox"]
        assert a["category_id"] == 1
        assert a["iscrowd"] in (0, 1)
        assert a["image_id"] in {1, 2, 3}
        assert x >= 0
        assert y >= 0
        assert x + w <= 640.01
        assert y + h <= 480.01
        assert w > 0
        assert h > 0
        assert 0 < a["area"] <= w * h + 1e-6
        if not a["iscrowd"]:
            assert x > 0
            assert y > 0
            assert x + w < 640
            assert y + h < 480


def test_pycocotools_reads_it(dataset: Path) -> None:
    from pycocotools.coco import COCO

    coco = COCO(str(dataset / "annotations.json"))
    assert len(coco.getImgIds()) == 3
    for ann in coco.loadAnns(coco.getAnnIds()):
        mask = coco.annToMask(ann)
        assert mask.shape == (480, 640)
        assert mask.sum() > 0


def test_deterministic_for_a_seed_whatever_the_workers(
    alien: ModuleType, dataset: Path, tmp_path: Path
) -> None:
    sys.path.insert(0, str(SCRIPT.parent))  # the spawned workers import the generator
    try:
        summary = alien.generate_dataset(tmp_path, 2, 11, jobs=2)
    finally:
        sys.path.remove(str(SCRIPT.parent))
    assert summary["images"] == 2
    first = json.loads((dataset / "annotations.json").read_text())
    again = json.loads((tmp_path / "annotations.json").read_text())
    assert again["images"] == first["images"][:2]
    assert again["annotations"] == [a for a in first["annotations"] if a["image_id"] <= 2]
    for name in ("rgb/alien_00000.png", "depth/alien_00001.png"):
        assert (tmp_path / name).read_bytes() == (dataset / name).read_bytes()


def test_hole_interiors_lie_in_their_boxes_and_read_deep(alien: ModuleType) -> None:
    """Every visible shaft pixel projects inside its rim's box; shafts read deeper or 0."""
    lib, tex = alien._assets(3)
    cam = alien.CameraModel.sample(np.random.default_rng([3, 0xCA]))
    checked = 0
    for index in range(8):
        rng = np.random.default_rng([3, index, 1])
        scene = alien.sample_scene(rng, cam, lib)
        access = [h for h in scene.holes if h.access]
        if not access:
            continue
        view = alien.PerspectiveView(cam, scene.C, scene.R)
        surf = alien.shade(rng, scene, view, tex)
        depth = alien.depth_sensor(rng, scene, cam, surf)
        anns = alien._annotate(scene, cam, surf)
        for hole in access:
            vv, uu = np.nonzero(surf.tag == hole.tag)
            if len(uu) < 50:
                continue
            inside = np.zeros(len(uu), bool)
            for a in anns:  # pixel (u, v) spans [u, u+1) x [v, v+1) in COCO coordinates
                x, y, w, h = a["bbox"]
                inside |= (
                    (uu + 0.5 >= x - 1.5)
                    & (uu + 0.5 <= x + w + 1.5)
                    & ((vv + 0.5 >= y - 1.5) & (vv + 0.5 <= y + h + 1.5))
                )
            assert inside.mean() > 0.99
            # the shaft reads deeper than the ground around it, or not at all
            ring = cv2.dilate((surf.tag == hole.tag).astype(np.uint8), np.ones((25, 25)))
            ring = (ring > 0) & (surf.tag != hole.tag) & (depth > 0)
            shaft = depth[(surf.tag == hole.tag)]
            deep = (shaft == 0) | (shaft > np.median(depth[ring]) + 300)
            assert deep.mean() > 0.5
            checked += 1
        if checked >= 2:
            break
    assert checked >= 1


def test_rejects_an_empty_request(alien: ModuleType, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="n must be"):
        alien.generate_dataset(tmp_path, 0, 1)


def test_a_recordings_frames_share_their_border_bands(dataset: Path) -> None:
    coco = json.loads((dataset / "annotations.json").read_text())
    sensors = [im["scene"]["sensor"] for im in coco["images"]]
    assert {s["recording"] for s in sensors} == {0}  # the first 10 frames: one recording
    assert len({(tuple(s["bands_ltrb_px"]), s["band_profile"]) for s in sensors}) == 1
    for im in coco["images"]:
        depth = cv2.imread(str(dataset / im["depth_file_name"]), cv2.IMREAD_UNCHANGED)
        left, top, right, bottom = im["scene"]["sensor"]["bands_ltrb_px"]
        assert not depth[:, :left].any() and not depth[:, 640 - right :].any()
        assert not depth[:top].any() and not depth[480 - bottom :].any()
        absorbing = im["scene"]["sensor"]["absorbing_stains"]
        for d in im["distractors"]:
            assert d["kind"] == "stain"
            x, y, w, h = d["bbox"]
            assert x >= 0 and y >= 0 and x + w <= 640 and y + h <= 480
            if "ir_unread" in d:
                assert absorbing[str(d["feature_id"])] == d["ir_unread"]


def test_absorbing_stains_swallow_55_to_76_percent(alien: ModuleType) -> None:
    from types import SimpleNamespace

    h, w = 120, 160
    stain = np.zeros((h, w), np.int32)
    stain[20:60, 20:80] = 1  # wet: always absorbing
    stain[70:110, 90:150] = 2  # dry: soot or char, or not
    ir = np.full((h, w), 0.5)
    ir[:10, :10] = 0.04  # a dark surface: 0.76 x (0.14 - ir) / 0.1
    s = SimpleNamespace(Z=np.full((h, w), 2.0), ir=ir, stain=stain)
    st = alien.Stain(np.zeros(2), np.ones(2), 0.0, 0.5, True)
    dry = alien.Stain(np.zeros(2), np.ones(2), 0.0, 0.5, False)
    offview = alien.Stain(np.zeros(2), np.ones(2), 0.0, 0.5, True)
    seen_dry = set()
    for seed in range(12):
        sc = SimpleNamespace(stains=[st, dry, offview])
        unread, absorbing = alien.absorbing_stains(np.random.default_rng(seed), sc, s)
        assert 1 in absorbing and 3 not in absorbing  # the third is not in view
        seen_dry.add(2 in absorbing)
        for sid, frac in absorbing.items():
            assert 0.55 <= frac <= 0.76
            assert np.allclose(unread[stain == sid], frac, atol=1e-3)
        assert unread[0, 0] == pytest.approx(0.76, abs=1e-6) and unread[15, 100] == 0
    assert seen_dry == {True, False}  # dry stains: some absorb, some do not
