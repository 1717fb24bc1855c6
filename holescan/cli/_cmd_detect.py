"""``holescan detect RGB.png DEPTH.png``: detect holes in one frame, print and draw them."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, replace
from pathlib import Path

from holescan.detect import DEFAULT, PAPER, SEARCHERS, CameraIntrinsics, DetectParams, detect_holes
from holescan.ground import draw_detections, read_camera, read_depth, read_rgb
from holescan.outputs import atomic_output, check_output, output_via_part


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
    p.add_argument(
        "--overlay", type=Path, help="write the image with boxes and segmentation (.png, .jpg)"
    )
    p.add_argument("--force", action="store_true", help="replace existing --json/--overlay")
    # --overwrite: the old spelling of --force, kept hidden for scripts written before
    p.add_argument("--overwrite", dest="force", action="store_true", help=argparse.SUPPRESS)
    add_detector_options(p)
    p.set_defaults(func=run)


_OVERLAY_SUFFIXES = {".png", ".jpg", ".jpeg"}


def run(args: argparse.Namespace) -> int:
    inputs = [p for p in (args.rgb, args.depth, args.camera) if p is not None]
    if args.json:  # checked before detecting: a bad output costs nothing
        check_output(args.json, inputs=inputs, suffixes={".json"}, force=args.force)
    if args.overlay:
        check_output(args.overlay, inputs=inputs, suffixes=_OVERLAY_SUFFIXES, force=args.force)
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
        with atomic_output(args.json, inputs=inputs, force=args.force) as f:
            f.write(json.dumps([asdict(d) for d in dets], indent=1).encode())
    if args.overlay:
        with output_via_part(
            args.overlay, inputs=inputs, suffixes=_OVERLAY_SUFFIXES, force=args.force
        ) as tmp:
            draw_detections(tmp, rgb, depth, camera, params, dets)
        print(f"overlay: {args.overlay}")
    return 0
