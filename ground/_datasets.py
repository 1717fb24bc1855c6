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
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from detect import CameraIntrinsics
from ground._images import read_camera, read_depth, read_rgb, write_depth, write_rgb
from holescan_errors import InputError

CATEGORY = {"id": 1, "name": "access_hole"}
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
    if key not in obj:
        raise InputError(f"{where}: missing '{key}'")
    return obj[key]


def load_dataset(path: Path | str) -> Dataset:
    """Read ``annotations.json`` and ``camera.json`` of a dataset folder (images lazily)."""
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
    anns: dict[int, list[tuple[Box, bool]]] = {}
    for i, a in enumerate(coco.get("annotations") or []):
        where = f"{ann_path}: annotation {i}"
        bbox = _field(a, "bbox", where)
        if not (isinstance(bbox, list) and len(bbox) == 4):
            raise InputError(f"{where}: bbox must be [x, y, w, h]")
        box = tuple(float(v) for v in bbox)
        anns.setdefault(int(_field(a, "image_id", where)), []).append(
            (box, bool(a.get("iscrowd", 0)))  # type: ignore[arg-type]
        )
    images = []
    for i, im in enumerate(coco["images"]):
        where = f"{ann_path}: image {i}"
        image_id = int(_field(im, "id", where))
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
    """Write samples as a dataset folder (created; existing files are replaced)."""
    root = Path(root)
    (root / "rgb").mkdir(parents=True, exist_ok=True)
    (root / "depth").mkdir(parents=True, exist_ok=True)
    images, annotations = [], []
    for image_id, s in enumerate(samples, start=1):
        if s.depth.shape != (camera.height, camera.width):
            raise InputError(f"{s.name}: depth {s.depth.shape} does not match the camera")
        write_rgb(root / "rgb" / f"{s.name}.png", s.rgb)
        write_depth(root / "depth" / f"{s.name}.png", s.depth)
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
    (root / "annotations.json").write_text(
        json.dumps(
            {"images": images, "annotations": annotations, "categories": [CATEGORY]}, indent=1
        )
    )
    (root / "camera.json").write_text(json.dumps(camera.to_dict(), indent=1))
    return root
