"""RGB-D hole datasets on disk, COCO-style.

```
DATASET/annotations.json  COCO: images[{id, file_name: "rgb/NAME.png",
                          depth_file_name: "depth/NAME.png", width, height}],
                          annotations[{id, image_id, category_id: 1, bbox: [x, y, w, h],
                          area, iscrowd}], categories[{id: 1, name: "access_hole"}]
DATASET/camera.json       {"width", "height", "fx", "fy", "cx", "cy", "depth_unit_m": 0.001}
DATASET/rgb/*.png         8-bit colour
DATASET/depth/*.png       16-bit, depth in mm, 0 = no reading
```

``iscrowd: 1`` marks a hole only partly in view: a detection on it is neither right nor
wrong (see :mod:`detect._evaluate`).
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from holescan.detect import CameraIntrinsics
from holescan.errors import InputError
from holescan.ground.images.files import read_camera, read_depth, read_rgb, write_depth, write_rgb
from holescan.outputs import atomic_output

__all__ = [
    "CATEGORY",
    "CATEGORY_ID",
    "Box",
    "Dataset",
    "DatasetImage",
    "Sample",
    "check_box",
    "load_dataset",
    "load_image_pair",
    "write_dataset",
]

log = logging.getLogger(__name__)

CATEGORY_ID = 1
CATEGORY = {"id": CATEGORY_ID, "name": "access_hole"}
Box = tuple[float, float, float, float]


@dataclass(frozen=True)
class DatasetImage:
    """One annotated RGB-D pair: paths, and its hole boxes (x, y, w, h pixels)."""

    id: int
    name: str
    rgb_path: Path
    depth_path: Path
    boxes: tuple[Box, ...]
    crowd: tuple[bool, ...]


@dataclass(frozen=True)
class Dataset:
    root: Path
    camera: CameraIntrinsics
    images: tuple[DatasetImage, ...]

    @property
    def n_holes(self) -> int:
        return sum(1 for img in self.images for c in img.crowd if not c)

    @property
    def n_crowd(self) -> int:
        return sum(1 for img in self.images for c in img.crowd if c)


@dataclass(frozen=True)
class Sample:
    """What :func:`write_dataset` writes for one image."""

    name: str
    rgb: npt.NDArray[np.uint8]
    depth: npt.NDArray[np.uint16]
    boxes: Sequence[Box]
    crowd: Sequence[bool]


def _field(obj: dict[str, Any], key: str, where: str) -> Any:
    if not isinstance(obj, dict):
        raise InputError(f"{where}: must be a JSON object, got {type(obj).__name__}")
    if key not in obj:
        raise InputError(f"{where}: missing '{key}'")
    return obj[key]


def _int_field(obj: dict[str, Any], key: str, where: str) -> int:
    value = _field(obj, key, where)
    if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value):
        raise InputError(f"{where}: '{key}' must be an integer, got {value!r}")
    return int(value)


def check_box(box: Sequence[Any], width: int, height: int, where: str) -> Box:
    """``box`` as four floats ``(x, y, w, h)``, or :class:`InputError` saying what is wrong.

    Refused: not four numbers, NaN or infinite values, zero or negative width or height,
    a box that does not overlap the ``width`` x ``height`` image at all.
    """
    if not (isinstance(box, list | tuple) and len(box) == 4):
        raise InputError(f"{where}: bbox must be [x, y, w, h], got {box!r}")
    if any(isinstance(v, bool) or not isinstance(v, int | float) for v in box):
        raise InputError(f"{where}: bbox values must be numbers, got {box!r}")
    x, y, w, h = (float(v) for v in box)
    if not all(np.isfinite(v) for v in (x, y, w, h)):
        raise InputError(f"{where}: bbox has a NaN or infinite value: {box!r}")
    if w <= 0 or h <= 0:
        raise InputError(f"{where}: bbox width and height must be > 0, got {box!r}")
    if x >= width or y >= height or x + w <= 0 or y + h <= 0:
        raise InputError(f"{where}: bbox {box!r} lies outside the {width}x{height} image")
    return (x, y, w, h)


def _zero_sized(bbox: Any) -> bool:
    return (
        isinstance(bbox, list)
        and len(bbox) == 4
        and all(isinstance(v, int | float) and math.isfinite(v) for v in bbox)
        and (bbox[2] == 0 or bbox[3] == 0)
    )


def _category_ids(coco: dict[str, Any], where: str) -> set[int]:
    cats = coco.get("categories")
    if cats is None:
        return {CATEGORY_ID}
    if not isinstance(cats, list):
        raise InputError(f"{where}: 'categories' must be a list")
    return {_int_field(c, "id", f"{where}: category {i}") for i, c in enumerate(cats)}


def load_dataset(path: Path | str) -> Dataset:
    """Read ``annotations.json`` and ``camera.json`` of a dataset folder (images lazily).

    Ground truth is checked record by record; a bad one raises :class:`InputError` naming
    it (``annotation 12 (id 13)``): boxes that are NaN, zero or negative in size or outside
    the image, duplicate image or annotation ids, annotations of an image the dataset does
    not list, categories it does not declare.
    """
    root = Path(path)
    if not root.is_dir():
        raise InputError(f"{root}: no such dataset folder")
    ann_path = root / "annotations.json"
    if not ann_path.is_file():
        raise InputError(f"{root}: no annotations.json (not a holescan/COCO dataset)")
    try:
        coco = json.loads(ann_path.read_text())
    except (OSError, ValueError) as err:
        raise InputError(f"{ann_path}: not readable JSON ({err})") from err
    if not isinstance(coco, dict) or not isinstance(coco.get("images"), list):
        raise InputError(f"{ann_path}: needs a COCO 'images' list")
    camera = read_camera(root / "camera.json")
    categories = _category_ids(coco, str(ann_path))
    image_ids: dict[int, int] = {}
    for i, im in enumerate(coco["images"]):
        where = f"{ann_path}: image {i}"
        image_id = _int_field(im, "id", where)
        if image_id in image_ids:
            raise InputError(
                f"{where}: duplicate image id {image_id} (also image {image_ids[image_id]})"
            )
        image_ids[image_id] = i
    raw_anns = coco.get("annotations") or []
    if not isinstance(raw_anns, list):
        raise InputError(f"{ann_path}: 'annotations' must be a list")
    anns: dict[int, list[tuple[Box, bool]]] = {}
    ann_ids: set[int] = set()
    for i, a in enumerate(raw_anns):
        where = f"{ann_path}: annotation {i}"
        if isinstance(a, dict) and "id" in a:
            ann_id = _int_field(a, "id", where)
            where += f" (id {ann_id})"
            if ann_id in ann_ids:
                raise InputError(f"{where}: duplicate annotation id")
            ann_ids.add(ann_id)
        image_id = _int_field(a, "image_id", where)
        if image_id not in image_ids:
            raise InputError(f"{where}: image_id {image_id} is not in the 'images' list")
        category = _int_field(a, "category_id", where) if "category_id" in a else CATEGORY_ID
        if category not in categories:
            raise InputError(
                f"{where}: unknown category_id {category} (declared: {sorted(categories)})"
            )
        crowd = bool(a.get("iscrowd", 0))
        bbox = _field(a, "bbox", where)
        if crowd and _zero_sized(bbox):
            # A sliver of a hole at the border rounded to nothing (older synthetic sets):
            # an ignore region of no area ignores nothing.
            log.warning("%s: zero-size crowd box %s skipped", where, bbox)
            continue
        box = check_box(bbox, camera.width, camera.height, where)
        anns.setdefault(image_id, []).append((box, crowd))
    images = []
    for i, im in enumerate(coco["images"]):
        where = f"{ann_path}: image {i}"
        image_id = int(im["id"])
        rgb_name = str(_field(im, "file_name", where))
        depth_name = str(_field(im, "depth_file_name", where))
        if (
            int(im.get("width", camera.width)) != camera.width
            or int(im.get("height", camera.height)) != camera.height
        ):
            raise InputError(
                f"{where}: size differs from camera.json ({camera.width}x{camera.height})"
            )
        boxes = anns.get(image_id, [])
        images.append(
            DatasetImage(
                id=image_id,
                name=Path(rgb_name).stem,
                rgb_path=root / rgb_name,
                depth_path=root / depth_name,
                boxes=tuple(b for b, _ in boxes),
                crowd=tuple(c for _, c in boxes),
            )
        )
    if not images:
        raise InputError(f"{ann_path}: the dataset has no image")
    return Dataset(root, camera, tuple(images))


def load_image_pair(
    dataset: Dataset, image: DatasetImage
) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.uint16]]:
    """The image's (rgb, depth), checked against the dataset's camera."""
    rgb, depth = read_rgb(image.rgb_path), read_depth(image.depth_path)
    want = (dataset.camera.height, dataset.camera.width)
    if rgb.shape[:2] != want or depth.shape != want:
        raise InputError(
            f"{image.name}: images are {rgb.shape[1]}x{rgb.shape[0]} / "
            f"{depth.shape[1]}x{depth.shape[0]}, camera.json says {want[1]}x{want[0]}"
        )
    return rgb, depth


def write_dataset(root: Path | str, camera: CameraIntrinsics, samples: Iterable[Sample]) -> Path:
    """Write samples as a dataset folder (created; existing files are replaced, each
    image through the output-path rule, so an interrupted run leaves no half image)."""
    root = Path(root)
    (root / "rgb").mkdir(parents=True, exist_ok=True)
    (root / "depth").mkdir(parents=True, exist_ok=True)
    images: list[dict[str, Any]] = []
    annotations: list[dict[str, Any]] = []
    for image_id, s in enumerate(samples, start=1):
        if s.depth.shape != (camera.height, camera.width):
            raise InputError(f"{s.name}: depth {s.depth.shape} does not match the camera")
        write_rgb(root / "rgb" / f"{s.name}.png", s.rgb, force=True)
        write_depth(root / "depth" / f"{s.name}.png", s.depth, force=True)
        images.append(
            {
                "id": image_id,
                "file_name": f"rgb/{s.name}.png",
                "depth_file_name": f"depth/{s.name}.png",
                "width": camera.width,
                "height": camera.height,
            }
        )
        for box, crowd in zip(s.boxes, s.crowd, strict=True):
            if crowd and min(round(float(box[2]), 2), round(float(box[3]), 2)) <= 0:
                continue  # a sliver at the border, nothing to ignore
            annotations.append(
                {
                    "id": len(annotations) + 1,
                    "image_id": image_id,
                    "category_id": 1,
                    "bbox": [round(float(v), 2) for v in box],
                    "area": round(float(box[2]) * float(box[3]), 2),
                    "iscrowd": int(bool(crowd)),
                }
            )
    doc = {"images": images, "annotations": annotations, "categories": [CATEGORY]}
    with atomic_output(root / "camera.json", force=True) as f:
        f.write(json.dumps(camera.to_dict(), indent=1).encode())
    with atomic_output(root / "annotations.json", force=True) as f:  # last: marks it complete
        f.write(json.dumps(doc, indent=1).encode())
    return root
