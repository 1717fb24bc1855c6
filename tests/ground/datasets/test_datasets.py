"""Dataset files: write -> read round trip, the synthetic generator, and bad datasets."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from holescan.detect import CameraIntrinsics
from holescan.errors import InputError
from holescan.ground.datasets import Sample, load_dataset, load_image_pair, write_dataset
from holescan.outputs import part_path
from holescan.sim import synth_dataset

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


# --- bad ground truth: each wrong record is named ---------------------------------------


def _coco(tmp_path: Path) -> tuple[Path, dict]:  # type: ignore[type-arg]
    root = write_dataset(tmp_path / "gt", CAM, _samples(3))
    return root, json.loads((root / "annotations.json").read_text())


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda c: c["annotations"][0].update(bbox=[10, 10, -5, 20]),
            r"annotation 0 \(id 1\).*> 0",
        ),
        (lambda c: c["annotations"][0].update(bbox=[10, 10, 0, 20]), r"annotation 0.*> 0"),
        (lambda c: c["annotations"][1].update(bbox=[10, float("nan"), 5, 5]), r"annotation 1.*NaN"),
        (lambda c: c["annotations"][0].update(bbox=[700, 10, 5, 5]), r"outside the 640x480"),
        (lambda c: c["annotations"][0].update(bbox=[1, 2, 3]), r"\[x, y, w, h\]"),
        (lambda c: c["annotations"][0].update(bbox=["a", 2, 3, 4]), r"numbers"),
        (
            lambda c: c["images"][2].update(id=c["images"][1]["id"]),
            r"image 2: duplicate image id 2",
        ),
        (lambda c: c["annotations"][1].update(id=1), r"annotation 1 \(id 1\): duplicate"),
        (lambda c: c["annotations"][0].update(image_id=99), r"image_id 99 is not in"),
        (lambda c: c["annotations"][0].update(category_id=7), r"unknown category_id 7"),
        (lambda c: c["annotations"][0].pop("image_id"), r"missing 'image_id'"),
    ],
)
def test_bad_ground_truth_names_the_record(tmp_path: Path, edit, message: str) -> None:  # type: ignore[no-untyped-def]
    root, coco = _coco(tmp_path)
    edit(coco)
    (root / "annotations.json").write_text(json.dumps(coco))  # NaN is written as NaN
    with pytest.raises(InputError, match=message):
        load_dataset(root)


def test_eval_cli_rejects_bad_ground_truth_in_one_line(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from holescan.cli import main

    root, coco = _coco(tmp_path)
    coco["annotations"][0]["bbox"] = [1, 1, -3, 4]
    (root / "annotations.json").write_text(json.dumps(coco))
    assert main(["eval", str(root), "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "annotation 0" in err[0]


# --- import-csv: the authors' groundTruth.csv form --------------------------------------


def _authors_folder(tmp_path: Path, layout: str = "flat") -> Path:
    """Three frames as the authors named them; two have a hole in the CSV, one has none."""
    import cv2

    src = tmp_path / "src"
    rng = np.random.default_rng(1)
    for stem in ("11_000000", "11_000060", "12_000000"):
        rgb = rng.integers(0, 256, (480, 640, 3), dtype=np.uint8)
        depth = rng.integers(500, 4000, (480, 640), dtype=np.uint16)
        if layout == "flat":
            rgb_p, depth_p = src / f"rgb_{stem}.png", src / f"depth_{stem}.png"
        else:
            rgb_p, depth_p = src / "rgb" / f"{stem}.png", src / "depth" / f"{stem}.png"
        rgb_p.parent.mkdir(parents=True, exist_ok=True)
        depth_p.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(rgb_p), rgb)
        cv2.imwrite(str(depth_p), depth)
    return src


def test_import_csv_authors_form(tmp_path: Path) -> None:
    from holescan.ground import import_csv_dataset

    src = _authors_folder(tmp_path)
    csv = tmp_path / "groundTruth.csv"
    # No header; MATLAB 1-based: x=1 is the first column; a box may end at the last pixel.
    csv.write_text(
        "rgb_11_000000.png,61,5,363,352\nrgb_11_000000.png,1,1,10,10\n"
        "rgb_12_000000.png,159,2,482,323\n"
    )
    out = import_csv_dataset(src, csv, tmp_path / "ds")
    assert not part_path(tmp_path / "ds").exists()
    ds = load_dataset(out)
    assert [im.name for im in ds.images] == ["11_000000", "11_000060", "12_000000"]
    assert ds.images[0].boxes == ((60.0, 4.0, 363.0, 352.0), (0.0, 0.0, 10.0, 10.0))
    assert ds.images[1].boxes == ()  # a frame without a hole is kept as a negative
    assert ds.images[2].boxes == ((158.0, 1.0, 482.0, 323.0),)
    assert ds.camera == CameraIntrinsics.xtion()
    rgb, depth = load_image_pair(ds, ds.images[2])
    import cv2

    want = cv2.imread(str(src / "depth_12_000000.png"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(depth, want) and rgb.shape == (480, 640, 3)


def test_import_csv_folders_header_and_zero_based(tmp_path: Path) -> None:
    from holescan.ground import import_csv_dataset

    src = _authors_folder(tmp_path, layout="folders")
    csv = tmp_path / "boxes.csv"
    csv.write_text("file,x,y,w,h\n11_000060.png,0,0,640,480\n\n")
    ds = load_dataset(import_csv_dataset(src, csv, tmp_path / "ds", origin=0))
    assert ds.images[1].boxes == ((0.0, 0.0, 640.0, 480.0),)


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        ("rgb_11_000000.png,61,5,363,352\nrgb_99_000000.png,1,1,5,5\n", r"line 2: unknown file"),
        ("rgb_11_000000.png,61,5,-3,352\n", r"line 1: box size must be positive"),
        ("rgb_11_000000.png,61,5,0,352\n", r"line 1: box size must be positive"),
        ("file,x,y,w,h\nrgb_11_000000.png,0,5,10,10\n", r"line 2: box corner .* outside"),
        ("rgb_11_000000.png,600,5,50,10\n", r"line 1: .*reaches past the 640x480"),
        ("rgb_11_000000.png,1,5,nan,10\n", r"line 1: w must be a finite number"),
        ("rgb_11_000000.png,1,5,ten,10\n", r"line 1: w must be a number"),
        ("rgb_11_000000.png,1,5,10\n", r"line 1: expected 5 fields"),
    ],
)
def test_import_csv_bad_rows_name_their_line(tmp_path: Path, rows: str, message: str) -> None:
    from holescan.ground import import_csv_dataset

    src = _authors_folder(tmp_path)
    csv = tmp_path / "gt.csv"
    csv.write_text(rows)
    with pytest.raises(InputError, match=message):
        import_csv_dataset(src, csv, tmp_path / "ds")
    assert not (tmp_path / "ds").exists() and not part_path(tmp_path / "ds").exists()


def test_import_csv_refuses_existing_output_and_unpaired_rgb(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from holescan.cli import main

    src = _authors_folder(tmp_path)
    csv = tmp_path / "gt.csv"
    csv.write_text("rgb_11_000000.png,61,5,363,352\n")
    out = tmp_path / "ds"
    assert main(["dataset", "import-csv", str(src), str(csv), str(out)]) == 0
    assert "3 images" in capsys.readouterr().out
    before = (out / "annotations.json").read_bytes()
    assert main(["dataset", "import-csv", str(src), str(csv), str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "already exists" in err[0]
    assert (out / "annotations.json").read_bytes() == before
    (src / "depth_11_000060.png").unlink()
    assert main(["dataset", "import-csv", str(src), str(csv), str(tmp_path / "ds2")]) == 2
    assert "rgb_11_000060.png: no depth image" in capsys.readouterr().err


def test_zero_size_crowd_sliver_is_skipped_not_fatal(tmp_path: Path) -> None:
    samples = _samples(2)
    samples.append(
        Sample("sliver", samples[0].rgb, samples[0].depth, [(220.19, 0.0, 0.05, 0.001)], [True])
    )
    write_dataset(tmp_path / "ds", CAM, samples)  # not written: it rounds to no area
    assert load_dataset(tmp_path / "ds").images[2].boxes == ()
    root, coco = _coco(tmp_path)
    coco["annotations"][1]["bbox"] = [220.19, 0.0, 0.05, 0.0]  # written by an older version
    (root / "annotations.json").write_text(json.dumps(coco))
    assert load_dataset(root).n_crowd == 0
