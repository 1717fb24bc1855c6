"""The statistics real structured-light frames were measured by, on any depth frames.

    python benchmarks/sensor_stats.py [DATASET ...] [--sim N] [--basic]
        [--recording PATH [--camera CAMERA.json]] ...

Prints one markdown column per source (the simulator's frames through the structured-light
model, ``--sim N`` frames; each DATASET folder's depth PNGs; each real recording holescan
reads, e.g. the OpenNI2 frame in ``tests/data/real/mrpt-openni2``) with: unread fraction, border
band widths (:func:`ground.recordings.depthstats.unread_stats`), the projector shadow's side
and width against ``1.2 f b (1/Z_near - 1/Z_far)``, the disparity quantisation step at 2 /
2.5 / 3 m, flat-surface noise against 1.425e-3 Z^2 and the flying-pixel rate at edge
crossings. ``docs/sensor-model.md`` has the table beside the real frames' figures.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

# Measure the checkout this script lives in, not whichever copy is installed.
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from holescan.ground.recordings.depthstats import unread_stats

FB_PX_M = 43.5  # f b of the Xtion / Kinect v1, px m


def _jump(z: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return 0.04 + 0.03 * z


def edge_stats(depth_mm: npt.NDArray[np.uint16], fx: float) -> dict[str, list[float]]:
    """Per row, read runs separated by a depth jump: which side the unread gap lies on, its
    width over the raw prediction, and whether a flying pixel sits at the crossing."""
    z = depth_mm.astype(np.float64) / 1000.0
    out: dict[str, list[float]] = {"gap_left": [], "gap_right": [], "excess": [], "flying": []}
    for row in z[::4]:
        read = np.flatnonzero(row > 0)
        if read.size < 10:
            continue
        gaps = np.diff(read) - 1
        for i in np.flatnonzero(gaps <= 60):
            a, b = read[i], read[i + 1]
            za, zb = row[a], row[b]
            if abs(za - zb) <= _jump(min(za, zb)):
                continue
            # plateaus: 3 pixels beyond the crossing on each side
            pa = row[max(0, a - 4) : a + 1]
            pb = row[b : b + 5]
            pa, pb = pa[pa > 0], pb[pb > 0]
            if pa.size < 3 or pb.size < 3:
                continue
            near_right = np.median(pb) < np.median(pa)
            zn, zf = min(np.median(pa), np.median(pb)), max(np.median(pa), np.median(pb))
            gap = int(gaps[i])
            if near_right:
                out["gap_left"].append(float(gap > 0))
                if gap > 0:
                    out["excess"].append(gap - 1.2 * fx / 580.0 * FB_PX_M * (1 / zn - 1 / zf))
            else:
                out["gap_right"].append(float(gap > 0))
            if gap == 0:
                # a flying pixel: the crossing's own pixels lie between the plateaus
                mid = row[max(a - 1, 0) : b + 2]
                tol = 3 * 1.425e-3 * zf * zf
                out["flying"].append(float(np.any((mid > zn + tol) & (mid < zf - tol))))
    return out


def quant_step(depth_mm: npt.NDArray[np.uint16], z_m: float) -> float | None:
    v = np.unique(depth_mm[np.abs(depth_mm.astype(np.float64) - 1000 * z_m) < 0.03 * 1000 * z_m])
    if v.size < 4:
        return None
    return float(np.median(np.diff(v.astype(np.float64))))


def flat_noise(depth_mm: npt.NDArray[np.uint16]) -> list[float]:
    """Noise over 1.425e-3 Z^2 from second differences along rows on smooth read surfaces."""
    z = depth_mm.astype(np.float64) / 1000.0
    a, b, c = z[:, :-2], z[:, 1:-1], z[:, 2:]
    ok = (a > 0) & (b > 0) & (c > 0)
    d2 = (a - 2 * b + c)[ok]
    zz = b[ok]
    model = 1.425e-3 * zz * zz
    keep = np.abs(d2) < 6 * model
    if keep.sum() < 1000:
        return []
    ratios = []
    for lo in np.arange(1.0, 4.0, 0.5):
        sel = keep & (zz >= lo) & (zz < lo + 0.5)
        if sel.sum() > 500:
            ratios.append(float(np.std(d2[sel]) / np.sqrt(6) / np.median(model[sel])))
    return ratios


def summarise(frames: list[npt.NDArray[np.uint16]], fx: float) -> dict[str, str]:
    us = [unread_stats(d) for d in frames]
    edges: dict[str, list[float]] = {"gap_left": [], "gap_right": [], "excess": [], "flying": []}
    noise: list[float] = []
    steps: dict[float, list[float]] = {2.0: [], 2.5: [], 3.0: []}
    for d in frames:
        for k, v in edge_stats(d, fx).items():
            edges[k] += v
        noise += flat_noise(d)
        for zm in steps:
            s = quant_step(d, zm)
            if s is not None:
                steps[zm].append(s)

    def rng(vals: list[float], fmt: str = "{:.0f}") -> str:
        if not vals:
            return "-"
        lo, hi = np.percentile(vals, [10, 90])
        return f"{fmt.format(lo)}-{fmt.format(hi)}"

    def pct(vals: list[float]) -> str:
        return f"{100 * np.mean(vals):.0f} %" if vals else "-"

    return {
        "frames": str(len(frames)),
        "unread (10-90 %)": rng([100 * u.unread for u in us]) + " %",
        "band right px": rng([u.right for u in us]),
        "band top px": rng([u.top for u in us]),
        "band bottom px": rng([u.bottom for u in us]),
        "band left px": rng([u.left for u in us]),
        "left near-edges with a gap": pct(edges["gap_left"]),
        "right near-edges with a gap": pct(edges["gap_right"]),
        "shadow width - raw prediction, px (median)": (
            f"{np.median(edges['excess']):+.1f}" if edges["excess"] else "-"
        ),
        "quantisation step at 2 / 2.5 / 3 m, mm": " / ".join(
            f"{np.median(v):.1f}" if v else "-" for v in steps.values()
        ),
        "flat noise / 1.425e-3 Z^2 (median)": f"{np.median(noise):.2f}" if noise else "-",
        "flying pixels at edge crossings": pct(edges["flying"]),
    }


REAL = {
    "frames": "3 (TUM, NYU, SUN)",
    "unread (10-90 %)": "7-19 %",
    "band right px": "28-43 (raw 8)",
    "band top px": "12-13",
    "band bottom px": "8-10",
    "band left px": "2-11",
    "left near-edges with a gap": "74-100 %",
    "right near-edges with a gap": "almost never",
    "shadow width - raw prediction, px (median)": "about -4 (TUM, registered)",
    "quantisation step at 2 / 2.5 / 3 m, mm": "12 / 18.5 / 26",
    "flat noise / 1.425e-3 Z^2 (median)": "0.8-1.0",
    "flying pixels at edge crossings": "1-18 %",
}


def _sim_frames(n: int, structured_light: bool) -> tuple[list[npt.NDArray[np.uint16]], float]:
    from holescan.detect import CameraIntrinsics
    from holescan.sim import synth_samples

    cam = CameraIntrinsics.xtion()
    frames = [s.depth for s in synth_samples(n, 77, cam, 5, structured_light=structured_light)]
    return frames, cam.fx


def _dataset_frames(root: Path, limit: int) -> tuple[list[npt.NDArray[np.uint16]], float]:
    cam = json.loads((root / "camera.json").read_text())
    coco = json.loads((root / "annotations.json").read_text())
    frames = []
    for im in coco["images"][:limit]:
        d = cv2.imread(str(root / im["depth_file_name"]), cv2.IMREAD_UNCHANGED)
        frames.append(np.asarray(d, np.uint16))
    return frames, float(cam["fx"])


def _recording_frames(
    path: Path, camera: Path | None, limit: int
) -> tuple[list[npt.NDArray[np.uint16]], float]:
    from holescan.ground import read_camera
    from holescan.ground.recordings import open_recording

    cam = read_camera(camera) if camera is not None else None
    frames = []
    with open_recording(path, camera=cam) as source:
        for frame in source:
            frames.append(np.asarray(frame.depth, np.uint16))
            if len(frames) >= limit:
                break
        fx = source.camera.fx
    return frames, float(fx)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="*", type=Path)
    ap.add_argument("--sim", type=int, default=12, help="simulated frames (0: none)")
    ap.add_argument("--limit", type=int, default=20, help="frames per dataset")
    ap.add_argument("--basic", action="store_true", help="also the basic depth model")
    ap.add_argument(
        "--recording",
        type=Path,
        action="append",
        default=[],
        help="a real recording (TUM folder, ROS bag, .oni, flight log); repeatable",
    )
    ap.add_argument(
        "--camera", type=Path, help="camera.json for the recordings that carry no intrinsics"
    )
    args = ap.parse_args(argv)
    from holescan.errors import InputError

    try:
        real = {p: _recording_frames(p, args.camera, args.limit) for p in args.recording}
    except (InputError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    cols: dict[str, dict[str, str]] = {"real Kinect v1 (FIELD-NOTES)": REAL}
    if args.sim:
        cols["sim, structured light"] = summarise(*_sim_frames(args.sim, True))
        if args.basic:
            cols["sim, basic"] = summarise(*_sim_frames(args.sim, False))
    for path, (frames, fx) in real.items():
        cols[f"real: {path.name}"] = summarise(frames, fx)
    for root in args.datasets:
        cols[root.name] = summarise(*_dataset_frames(root, args.limit))
    names = list(cols)
    print("| statistic | " + " | ".join(names) + " |")
    print("|---" * (len(names) + 1) + "|")
    for key in REAL:
        print(f"| {key} | " + " | ".join(cols[n][key] for n in names) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
