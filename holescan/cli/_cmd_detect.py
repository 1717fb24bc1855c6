"""``holescan detect RGB.png DEPTH.png`` (one frame: print and draw its holes) or
``holescan detect RECORDING`` (every frame of a TUM folder, ROS bag, ``.oni`` or flight log)."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict, replace
from pathlib import Path

from holescan.detect import DEFAULT, PAPER, SEARCHERS, CameraIntrinsics, DetectParams, detect_holes
from holescan.errors import InputError
from holescan.ground import draw_detections, read_camera, read_depth, read_rgb
from holescan.outputs import atomic_output, check_output


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
    p = sub.add_parser(
        "detect",
        help="detect access holes in one RGB + depth pair, or in every frame of a recording",
        description="RGB DEPTH: one frame. RECORDING alone: every frame of a TUM RGB-D folder "
        "(rgb.txt, depth.txt), a ROS 1 .bag or ROS 2 bag folder (sensor_msgs/Image colour and "
        "registered depth, CameraInfo), an OpenNI .oni file or a holescan flight log .mcap, "
        "recognised by its content (docs/real-recordings.md).",
    )
    p.add_argument("rgb", type=Path, help="8-bit colour image, or a RECORDING")
    p.add_argument(
        "depth",
        type=Path,
        nargs="?",
        help="16-bit depth PNG, millimetres, 0 = no reading (none with a RECORDING)",
    )
    p.add_argument(
        "--camera",
        type=Path,
        help="camera.json (default: the recording's own, else Xtion intrinsics)",
    )
    p.add_argument(
        "--every", type=int, default=1, metavar="N", help="RECORDING: every N-th frame (1)"
    )
    p.add_argument("--max-frames", type=int, metavar="N", help="RECORDING: at most N frames")
    p.add_argument(
        "--max-dt",
        type=float,
        default=0.02,
        metavar="S",
        help="RECORDING: largest colour-depth time difference of a pair, s (0.02)",
    )
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
    if args.depth is None:
        return run_recording(args)
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
        draw_detections(
            args.overlay, rgb, depth, camera, params, dets, inputs=inputs, force=args.force
        )
        print(f"overlay: {args.overlay}")
    return 0


def run_recording(args: argparse.Namespace) -> int:
    """``holescan detect RECORDING``: the candidates of every frame; --json: per frame."""
    from holescan.ground.recordings import detect_recording, open_recording

    recording = args.rgb
    inputs = [p for p in (recording, args.camera) if p is not None]
    if args.overlay:
        raise InputError("--overlay draws one frame: give RGB DEPTH, not a recording")
    if args.json:
        check_output(args.json, inputs=inputs, suffixes={".json"}, force=args.force)
    camera = read_camera(args.camera) if args.camera else None
    params = params_from_args(args, args.superpixels)
    source = open_recording(recording, camera=camera, max_dt_s=args.max_dt)
    frames: list[dict[str, object]] = []
    n_frames = n_dets = 0
    with source:
        for fd in detect_recording(source, params, every=args.every, max_frames=args.max_frames):
            n_frames += 1
            n_dets += len(fd.detections)
            note = " (no depth)" if fd.no_depth else ""
            print(f"frame {fd.index}: {len(fd.detections)} candidate hole(s){note}")
            for i, d in enumerate(fd.detections, 1):
                print(f"  {i}: box {d.box} {d.explain()}")
            frames.append(
                {
                    "frame_index": fd.index,
                    "t_sensor_ns": fd.t_sensor_ns,
                    "no_depth": fd.no_depth,
                    "detections": [asdict(d) for d in fd.detections],
                }
            )
    c = source.camera
    print(
        f"{recording}: {n_frames} frame(s), {n_dets} candidate(s) ({params.mode.value} mode, "
        f"{params.searcher.name}; camera {c.width}x{c.height} fx {c.fx:.1f})"
    )
    if args.json:
        with atomic_output(args.json, inputs=inputs, force=args.force) as f:
            f.write(json.dumps(frames, indent=1).encode())
    return 0
