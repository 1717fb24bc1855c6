"""``holescan detect RGB.png DEPTH.png``: detect holes in one frame, print and draw them."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, replace
from pathlib import Path

from detect import DEFAULT, PAPER, SEARCHERS, CameraIntrinsics, DetectParams, detect_holes
from ground import draw_detections, read_camera, read_depth, read_rgb


def add_detector_options(p: argparse.ArgumentParser) -> None:
    """Options shared by every verb that runs the detector."""
    p.add_argument(
        "--mode",
        choices=("default", "paper"),
        default="default",
        help="holescan's detector (default) or the paper's method",
    )
    p.add_argument(
        "--searcher",
        choices=sorted(SEARCHERS),
        default="human",
        help="who must fit through the hole (sets size and depth thresholds)",
    )


def params_from_args(args: argparse.Namespace, superpixels: int | None = None) -> DetectParams:
    base = PAPER if args.mode == "paper" else DEFAULT
    params = base.with_searcher(args.searcher)
    return replace(params, superpixels=superpixels) if superpixels else params


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("detect", help="detect access holes in one RGB + depth pair")
    p.add_argument("rgb", type=Path, help="8-bit colour image")
    p.add_argument("depth", type=Path, help="16-bit depth PNG, millimetres, 0 = no reading")
    p.add_argument("--camera", type=Path, help="camera.json (default: Xtion intrinsics)")
    p.add_argument("--superpixels", type=int, default=9, help="K for paper mode")
    p.add_argument("--json", type=Path, help="write the detections as JSON")
    p.add_argument("--overlay", type=Path, help="write the image with boxes and segmentation")
    add_detector_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    rgb, depth = read_rgb(args.rgb), read_depth(args.depth)
    if args.camera:
        camera = read_camera(args.camera)
    else:
        camera = CameraIntrinsics.xtion(depth.shape[1], depth.shape[0])
    params = params_from_args(args, args.superpixels)
    dets = detect_holes(rgb, depth, camera, params)
    print(f"{len(dets)} candidate hole(s) ({params.mode.value} mode, {params.searcher.name})")
    for i, d in enumerate(dets, 1):
        print(f"  {i}: box {d.box} {d.explain()}")
    if args.json:
        args.json.write_text(json.dumps([asdict(d) for d in dets], indent=1))
    if args.overlay:
        draw_detections(args.overlay, rgb, depth, camera, params, dets)
        print(f"overlay: {args.overlay}")
    return 0
