"""``holescan eval DATASET``: run the detector over a dataset and print AP (both rules)."""

from __future__ import annotations

import argparse
import os
import tempfile
from dataclasses import replace
from pathlib import Path

from holescan.cli._cmd_detect import add_detector_options, params_from_args
from holescan.cli.progress import Progress
from holescan.errors import InputError
from holescan.ground import (
    JSON_SUFFIXES,
    PLOT_SUFFIXES,
    EvalReport,
    brier_score,
    calibration_outcomes,
    format_table,
    load_dataset,
    plot_pr,
    plot_reliability,
    read_camera,
    run_detector,
    write_coco_results,
)
from holescan.ground.recordings import recording_dataset
from holescan.outputs import check_output


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "eval",
        help="evaluate the detector on a COCO-style RGB-D dataset",
        description="Runs the detector on every image and prints AP under IoU > 0.5 and the "
        "authors' rule (intersection / larger box > 0.5), recall and precision at full recall.",
    )
    p.add_argument(
        "dataset",
        type=Path,
        nargs="?",
        help="dataset folder (annotations.json, camera.json), or a RECORDING (TUM RGB-D "
        "folder, ROS 1/ROS 2 bag, .oni, flight log) with --boxes",
    )
    p.add_argument(
        "--boxes",
        type=Path,
        metavar="CSV",
        help="with a RECORDING: its hole boxes, frame,x,y,w,h per row (frame index, "
        "frame_NNNNNN or a TUM colour file; x, y 1-based unless --zero-based)",
    )
    p.add_argument("--zero-based", action="store_true", help="--boxes x, y count from 0")
    p.add_argument("--camera", type=Path, help="with a RECORDING: camera.json to use instead")
    p.add_argument(
        "--synthetic",
        type=int,
        metavar="N",
        nargs="?",
        const=60,
        help="instead of DATASET: render N synthetic frames (default 60, seed 1) into "
        "./holescan-synth-N and compare paper mode, default mode and the baseline",
    )
    p.add_argument(
        "--superpixels",
        default="9",
        help="K for paper mode, or a list (9,11,13,15,18,20) for the Table I sweep",
    )
    p.add_argument(
        "--compare",
        action="store_true",
        help="also run the other mode and the naive depth-threshold baseline",
    )
    p.add_argument("--detections", type=Path, help="write COCO results JSON (the first run)")
    p.add_argument("--plot", type=Path, help="write a precision-recall plot (.png, .pdf, .svg)")
    p.add_argument(
        "--force", action="store_true", help="replace existing --detections/--plot files"
    )
    # --overwrite: the old spelling of --force, kept hidden for scripts written before
    p.add_argument("--overwrite", dest="force", action="store_true", help=argparse.SUPPRESS)
    p.add_argument(
        "--reliability",
        type=Path,
        metavar="PNG",
        help="write the reliability diagram of default mode's p_hole on this dataset and "
        "print its Brier score (with --plot and no --reliability: PR.png and "
        "PR-reliability.png)",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=os.cpu_count() or 1,
        help="detector processes (default: all cores)",
    )
    add_detector_options(p)
    p.set_defaults(func=run)


def _parse_ks(text: str) -> list[int]:
    try:
        ks = [int(k) for k in text.split(",") if k.strip()]
    except ValueError as err:
        raise InputError(f"--superpixels must be integers like 9 or 9,11,13, got {text!r}") from err
    if not ks or min(ks) < 2:
        raise InputError(f"--superpixels needs K >= 2, got {text!r}")
    return ks


def run(args: argparse.Namespace) -> int:
    if args.reliability is None and args.plot:
        args.reliability = args.plot.with_name(f"{args.plot.stem}-reliability{args.plot.suffix}")
    outputs = (
        (JSON_SUFFIXES, args.detections),
        (PLOT_SUFFIXES, args.plot),
        (PLOT_SUFFIXES, args.reliability),
    )
    for suffixes, path in outputs:  # before minutes of detection
        if path is not None:
            check_output(path, suffixes=suffixes, force=args.force)
    if args.synthetic is not None:
        if args.dataset is not None:
            raise InputError("give either DATASET or --synthetic, not both")
        from holescan.sim import synth_dataset

        args.dataset = Path(f"holescan-synth-{args.synthetic}")
        args.compare = True
        if not (args.dataset / "annotations.json").is_file():
            print(f"rendering {args.synthetic} synthetic frames into {args.dataset}/ ...")
            bar = Progress()
            synth_dataset(
                args.dataset, args.synthetic, seed=1, progress=lambda i, n: bar(i, n, "rendering ")
            )
            bar.done()
    if args.dataset is None:
        raise InputError("give a DATASET folder or --synthetic")
    if args.boxes is None:
        return _evaluate(args, args.dataset)
    if (args.dataset / "annotations.json").is_file():
        raise InputError(
            f"{args.dataset}: a dataset folder has its boxes: --boxes goes with a RECORDING"
        )
    with tempfile.TemporaryDirectory(prefix="holescan-eval-") as tmp:
        # the recording's frames and --boxes as a scratch dataset, gone after the run
        camera = read_camera(args.camera) if args.camera else None
        origin = 0 if args.zero_based else 1
        recording_dataset(args.dataset, args.boxes, tmp, camera=camera, origin=origin)
        shown = args.dataset
        args.dataset = Path(tmp)
        return _evaluate(args, shown)


def _evaluate(args: argparse.Namespace, shown: Path) -> int:
    """Run and print the evaluation of the dataset folder ``args.dataset`` (``shown``: what
    the user gave, for the printed lines)."""
    dataset = load_dataset(args.dataset)
    if not any(img.boxes for img in dataset.images):
        raise InputError(f"{shown}: the dataset has no annotated hole; nothing to evaluate")
    ks = _parse_ks(args.superpixels)
    base = params_from_args(args)
    runs: list[tuple[str, object]] = []
    if base.mode.value == "paper" or len(ks) > 1:
        paper = params_from_args(argparse.Namespace(mode="paper", searcher=args.searcher))
        runs += [(f"paper K={k}", replace(paper, superpixels=k)) for k in ks]
    if base.mode.value == "default" or args.compare:
        runs.append(
            (
                "default",
                params_from_args(argparse.Namespace(mode="default", searcher=args.searcher)),
            )
        )
    if args.compare:
        if not any(name.startswith("paper") for name, _ in runs):
            paper = params_from_args(argparse.Namespace(mode="paper", searcher=args.searcher))
            runs.append((f"paper K={ks[0]}", replace(paper, superpixels=ks[0])))
        runs.append(("baseline (depth threshold)", None))
    reports: list[EvalReport] = []
    n = len(dataset.images)
    for name, params in runs:
        bar = Progress()

        def progress(i: int, total: int, name: str = name, bar: Progress = bar) -> None:
            bar(i, total, f"{name}: ")

        reports.append(run_detector(dataset, params, name, progress, args.workers))  # type: ignore[arg-type]
        bar.done()
    n_gt = reports[0].iou.n_gt
    print(f"{shown}: {n} images, {n_gt} access holes (crowd boxes ignored)")
    print(format_table(reports))
    if args.detections:
        write_coco_results(args.detections, reports[0].detections, force=args.force)
        print(f"detections ({reports[0].name}): {args.detections}")
    if args.plot:
        title = f"{shown.name}: {n} images, {n_gt} holes"
        plot_pr(args.plot, reports, title, force=args.force)
        print(f"precision-recall plot: {args.plot}")
    reliability = args.reliability
    default = next((r for r in reports if r.name == "default"), None)
    if default is not None and reliability is not None:
        p, is_true = calibration_outcomes(default.iou)
        brier = brier_score(p, is_true)
        print(f"default mode p_hole: Brier score {brier:.4f} over {len(p)} detections")
        title = f"{shown.name}: {len(p)} detections, Brier {brier:.3f}"
        plot_reliability(reliability, p, is_true, title, force=args.force)
        print(f"reliability diagram (p_hole): {reliability}")
    return 0
