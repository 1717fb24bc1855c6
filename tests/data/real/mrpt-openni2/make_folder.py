"""Rebuild this TUM RGB-D folder from Debian's ``mrpt-common`` (see README.md beside this file).

    apt-get install mrpt-common mrpt-apps      # the rawlog and MRPT's own rawlog-edit
    python3 tests/data/real/mrpt-openni2/make_folder.py OUT

MRPT's ``rawlog-edit --externalize --txt-externals`` writes the one
``CObservation3DRangeScan`` of ``tests_rgbd.rawlog`` as its colour image (PNG) and its range
image (text, millimetres: the rawlog's ``rangeUnits`` are 0.001 m); this script stores them
as a TUM folder: the colour PNG as written by rawlog-edit, the depth as a 16-bit PNG at 5000
per metre (mm x 5, lossless), ``rgb.txt``/``depth.txt`` at the observation's timestamp and
``camera.json`` with the rawlog's colour-camera intrinsics. OUT must not exist yet.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

RAWLOG = Path("/usr/share/mrpt/datasets/tests_rgbd.rawlog")
STAMP = "1462879443.617188"  # the observation's timestamp (rawlog-edit --info), s
# [INTENSITY_CAM_PARAMS] of the observation (rawlog-edit --describe)
CAMERA = {"width": 640, "height": 480, "fx": 521.17923, "fy": 493.03303, "cx": 322.51599,
          "cy": 259.05597}  # fmt: skip


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__.splitlines()[2].strip(), file=sys.stderr)
        return 2
    out = Path(sys.argv[1])
    if out.exists():
        print(f"{out}: exists; give a new folder", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        shutil.copy(RAWLOG, work / "in.rawlog")
        subprocess.run(
            ["rawlog-edit", "--externalize", "--txt-externals", "--image-format", "png",
             "-i", "in.rawlog", "-o", "out.rawlog"],
            cwd=work, check=True, stdout=subprocess.DEVNULL,
        )  # fmt: skip
        ext = work / "out_Images"
        (rgb_png,) = ext.glob("*_INT.png")
        (ranges_txt,) = ext.glob("*_RANGES.txt")
        mm = np.loadtxt(ranges_txt)
        if mm.shape != (480, 640) or (mm != np.round(mm)).any() or mm.max() * 5 > 65535:
            print(f"{ranges_txt.name}: not a 640x480 whole-mm range image", file=sys.stderr)
            return 1
        (out / "rgb").mkdir(parents=True)
        (out / "depth").mkdir()
        shutil.copy(rgb_png, out / "rgb" / f"{STAMP}.png")
        tum = (mm * 5).astype(np.uint16)
        cv2.imwrite(str(out / "depth" / f"{STAMP}.png"), tum, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    (out / "rgb.txt").write_text(
        f"# colour images (MRPT tests_rgbd.rawlog)\n{STAMP} rgb/{STAMP}.png\n"
    )
    (out / "depth.txt").write_text(
        f"# depth images, 5000 per metre (MRPT tests_rgbd.rawlog)\n{STAMP} depth/{STAMP}.png\n"
    )
    (out / "camera.json").write_text(json.dumps(CAMERA, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
