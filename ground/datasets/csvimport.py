"""Real RGB-D frames plus a CSV of hole boxes, imported as a dataset (COCO layout).

The input is what Kong et al. published for their 254 Xtion frames: a folder of PNG pairs
and a ``groundTruth.csv`` with one hole per row, ``file,x,y,w,h`` in MATLAB pixels.

How files pair (checked in this order for every colour image):

* ``FOLDER/rgb/NAME`` with ``FOLDER/depth/NAME`` (same name), or with
  ``FOLDER/depth/depth_ID.png`` when NAME is ``rgb_ID.png``;
* flat: ``FOLDER/rgb_ID.png`` with ``FOLDER/depth_ID.png`` (the authors' naming;
  ``rgb-ID``/``depth-ID`` too).

A colour image without a depth partner is an error. Every pair found is imported, also
those the CSV does not mention: they are frames without a hole (the authors' 88 negatives),
and a detection on them is a false positive.

The CSV: one row per hole, ``file,x,y,w,h``; an optional header row (recognised by a
non-numeric ``x``); ``file`` is the colour image's name (``rgb_11_000000.png``), with or
without the extension or the ``rgb/`` folder. ``x, y`` is the top-left pixel, 1-based
(MATLAB, ``origin=1``; pass ``origin=0`` for 0-based files), ``w, h`` the size in pixels, so
the box covers pixels ``x .. x+w-1``; it is stored as ``[x - origin, y - origin, w, h]`` in
our convention (pixel ``i`` spans ``[i, i+1)``). A row naming an unknown file, with a box
outside the image, a zero, negative or non-numeric size raises :class:`InputError` with
its line number.

The output folder must not exist: the dataset is written to ``.OUT.part`` and renamed when
complete (:func:`outputs.folder_via_part`, the project's output rule for folders), so an
interrupted import never leaves a half dataset under the final name.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from holescan.detect import CameraIntrinsics
from holescan.errors import InputError
from holescan.ground.datasets.coco import CATEGORY, CATEGORY_ID, Box, load_dataset
from holescan.ground.images.files import read_depth, read_rgb
from holescan.outputs import folder_via_part

__all__ = ["CsvBox", "FramePair", "find_pairs", "import_csv_dataset", "read_box_csv"]

_PREFIXES = (("rgb_", "depth_"), ("rgb-", "depth-"))
_IMAGE_EXT = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass(frozen=True)
class FramePair:
    """One colour image and its depth partner; ``name`` is the stem without ``rgb_``."""

    name: str
    rgb_path: Path
    depth_path: Path


@dataclass(frozen=True)
class CsvBox:
    """One row of the box CSV: its line number, the file it names, the box (0-based)."""

    line: int
    file: str
    box: Box


def _strip_prefix(stem: str) -> str:
    for rgb, _ in _PREFIXES:
        if stem.startswith(rgb):
            return stem[len(rgb) :]
    return stem


def _depth_names(rgb_name: str) -> list[str]:
    names = []
    for rgb, depth in _PREFIXES:
        if rgb_name.startswith(rgb):
            stem = Path(rgb_name).stem
            names += [depth + stem[len(rgb) :] + ".png", depth + rgb_name[len(rgb) :]]
    return list(dict.fromkeys(names))


def find_pairs(folder: Path) -> list[FramePair]:
    """Every colour image of ``folder`` with its depth partner (module docstring), by name."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{folder}: no such folder")
    pairs: list[FramePair] = []
    rgb_dir, depth_dir = folder / "rgb", folder / "depth"
    if rgb_dir.is_dir():
        for p in sorted(rgb_dir.iterdir()):
            if p.suffix.lower() not in _IMAGE_EXT:
                continue
            tried = [depth_dir / p.name, depth_dir / (p.stem + ".png")]
            tried += [depth_dir / n for n in _depth_names(p.name)]
            pairs.append(_pair(p, tried))
    for p in sorted(folder.iterdir()):
        if p.is_file() and p.suffix.lower() in _IMAGE_EXT and _depth_names(p.name):
            pairs.append(_pair(p, [folder / n for n in _depth_names(p.name)]))
    if not pairs:
        raise InputError(
            f"{folder}: no colour images found (expected rgb/NAME.png + depth/NAME.png, "
            "or rgb_ID.png + depth_ID.png)"
        )
    names: dict[str, Path] = {}
    for pair in pairs:
        if pair.name in names:
            raise InputError(
                f"{pair.rgb_path} and {names[pair.name]}: two colour images for frame '{pair.name}'"
            )
        names[pair.name] = pair.rgb_path
    return pairs


def _pair(rgb: Path, tried: list[Path]) -> FramePair:
    for d in dict.fromkeys(tried):
        if d.is_file():
            return FramePair(_strip_prefix(rgb.stem), rgb, d)
    looked = ", ".join(str(t) for t in dict.fromkeys(tried))
    raise InputError(f"{rgb}: no depth image for it (looked for {looked})")


def _number(text: str, what: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise InputError(f"{where}: {what} must be a number, got {text!r}") from err
    if not math.isfinite(value):
        raise InputError(f"{where}: {what} must be a finite number, got {text!r}")
    return value


def read_box_csv(path: Path, origin: int = 1) -> list[CsvBox]:
    """Rows of a ``file,x,y,w,h`` CSV as 0-based boxes (module docstring); empty lines skipped.

    Only the syntax is checked here (five fields, numbers, positive size, ``x, y >= origin``);
    :func:`import_csv_dataset` checks file names and image bounds.
    """
    if origin not in (0, 1):
        raise InputError(f"origin must be 0 or 1, got {origin}")
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except FileNotFoundError as err:
        raise InputError(f"{path}: no such file") from err
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: not a readable text file ({err})") from err
    rows: list[CsvBox] = []
    for line_no, row in enumerate(csv.reader(text.splitlines()), start=1):
        fields = [f.strip() for f in row]
        while fields and fields[-1] == "":
            fields.pop()
        if not fields:
            continue
        where = f"{path}, line {line_no}"
        if len(fields) != 5:
            raise InputError(f"{where}: expected 5 fields file,x,y,w,h, got {len(fields)}")
        if line_no == 1 and not _is_number(fields[1]):
            continue  # header row
        x, y, w, h = (_number(v, k, where) for v, k in zip(fields[1:], "xywh", strict=True))
        if w <= 0 or h <= 0:
            raise InputError(f"{where}: box size must be positive, got w={w:g} h={h:g}")
        if x < origin or y < origin:
            raise InputError(
                f"{where}: box corner ({x:g}, {y:g}) is outside the image (first pixel is "
                f"{origin}, {origin})"
            )
        rows.append(CsvBox(line_no, fields[0], (x - origin, y - origin, w, h)))
    return rows


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _lookup(pairs: dict[str, FramePair], file: str) -> FramePair | None:
    name = Path(file.replace("\\", "/")).name
    stem = Path(name).stem if Path(name).suffix.lower() in _IMAGE_EXT else name
    return pairs.get(_strip_prefix(stem))


def import_csv_dataset(
    folder: Path,
    csv_path: Path,
    out: Path,
    camera: CameraIntrinsics | None = None,
    origin: int = 1,
) -> Path:
    """Write the frames of ``folder`` and the boxes of ``csv_path`` as a dataset at ``out``.

    ``camera`` defaults to the Xtion's intrinsics at the images' size. Every image is read
    (8-bit colour, 16-bit depth, one size for all) before anything is written. Refuses an
    existing ``out`` (at once, before reading); writes ``.OUT.part`` and renames it
    (:func:`outputs.folder_via_part`). Returns ``out``.
    """
    out = Path(out)
    with folder_via_part(out, inputs=[folder, csv_path]) as part:
        pairs = {p.name: p for p in find_pairs(folder)}
        rows = read_box_csv(csv_path, origin)
        first = next(iter(pairs.values()))
        h0, w0 = read_depth(first.depth_path).shape
        cam = camera or CameraIntrinsics.xtion(w0, h0)
        boxes: dict[str, list[Box]] = {}
        for r in rows:
            pair = _lookup(pairs, r.file)
            where = f"{csv_path}, line {r.line}"
            if pair is None:
                raise InputError(
                    f"{where}: unknown file {r.file!r} (no such colour image in {folder})"
                )
            x, y, w, h = r.box
            if x + w > cam.width or y + h > cam.height:
                raise InputError(
                    f"{where}: box {r.file} x={x + origin:g} y={y + origin:g} w={w:g} h={h:g} "
                    f"reaches past the {cam.width}x{cam.height} image"
                )
            boxes.setdefault(pair.name, []).append(r.box)
        for pair in pairs.values():
            rgb, depth = read_rgb(pair.rgb_path), read_depth(pair.depth_path)
            if rgb.shape[:2] != (cam.height, cam.width) or depth.shape != (cam.height, cam.width):
                raise InputError(
                    f"{pair.rgb_path}: colour {rgb.shape[1]}x{rgb.shape[0]} / depth "
                    f"{depth.shape[1]}x{depth.shape[0]}, expected {cam.width}x{cam.height}"
                )
        _write(part, cam, list(pairs.values()), boxes)
        load_dataset(part)  # what we wrote must read back
    return out


def _write(
    root: Path, cam: CameraIntrinsics, pairs: list[FramePair], boxes: dict[str, list[Box]]
) -> None:
    (root / "rgb").mkdir()
    (root / "depth").mkdir()
    images: list[dict[str, Any]] = []
    annotations: list[dict[str, Any]] = []
    for image_id, p in enumerate(sorted(pairs, key=lambda p: p.name), start=1):
        rgb_name = f"rgb/{p.name}{p.rgb_path.suffix.lower()}"
        depth_name = f"depth/{p.name}.png"
        shutil.copyfile(p.rgb_path, root / rgb_name)
        shutil.copyfile(p.depth_path, root / depth_name)
        images.append(
            {
                "id": image_id,
                "file_name": rgb_name,
                "depth_file_name": depth_name,
                "width": cam.width,
                "height": cam.height,
                "source_file": p.rgb_path.name,
            }
        )
        for box in boxes.get(p.name, []):
            annotations.append(
                {
                    "id": len(annotations) + 1,
                    "image_id": image_id,
                    "category_id": CATEGORY_ID,
                    "bbox": [float(v) for v in box],
                    "area": float(box[2] * box[3]),
                    "iscrowd": 0,
                }
            )
    doc = {"images": images, "annotations": annotations, "categories": [CATEGORY]}
    (root / "annotations.json").write_text(json.dumps(doc, indent=1))
    (root / "camera.json").write_text(json.dumps(cam.to_dict(), indent=1))
