"""``holescan dataset synth|import-csv|info``: make, import and inspect RGB-D hole datasets."""

from __future__ import annotations

import argparse
from pathlib import Path

from holescan.cli.progress import Progress
from holescan.ground import import_csv_dataset, load_dataset, read_camera
from holescan.outputs import check_folder


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("dataset", help="make or inspect an RGB-D hole dataset")
    verbs = p.add_subparsers(dest="dataset_verb", required=True, metavar="ACTION")
    s = verbs.add_parser("synth", help="render a synthetic rubble dataset with ground truth")
    s.add_argument("out", type=Path, help="output folder")
    s.add_argument("--n", type=int, default=60, help="number of images (default 60)")
    s.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    s.add_argument(
        "--sensor",
        choices=("structured-light", "basic"),
        default="structured-light",
        help="depth model: the measured structured-light model (default; border bands, "
        "projector shadows, IR dropouts, misregistration) or the basic one, for comparison",
    )
    s.set_defaults(func=run_synth)
    c = verbs.add_parser(
        "import-csv",
        help="import real RGB-D PNG pairs and a file,x,y,w,h CSV of hole boxes",
        description="Pairs rgb/NAME.png with depth/NAME.png, or rgb_ID.png with depth_ID.png "
        "in one folder; every pair is imported (frames the CSV does not name have no hole). "
        "CSV rows: file,x,y,w,h (an optional header row), x, y the top-left pixel, 1-based "
        "as in MATLAB and the authors' groundTruth.csv. OUT must not exist.",
    )
    c.add_argument("folder", type=Path, help="folder of colour and depth PNGs")
    c.add_argument("csv", type=Path, help="CSV of hole boxes: file,x,y,w,h per row")
    c.add_argument("out", type=Path, help="dataset folder to create (must not exist)")
    c.add_argument(
        "--camera", type=Path, help="camera.json of the frames (default: Xtion at their size)"
    )
    c.add_argument(
        "--zero-based", action="store_true", help="x, y in the CSV count from 0, not from 1"
    )
    c.set_defaults(func=run_import_csv)
    i = verbs.add_parser("info", help="count images and holes of a dataset")
    i.add_argument("dataset", type=Path)
    i.set_defaults(func=run_info)


def run_synth(args: argparse.Namespace) -> int:
    from holescan.sim import synth_dataset

    existing = args.out.absolute()
    while not existing.exists():  # the folders synth would create must be creatable
        existing = existing.parent
    check_folder(existing)
    bar = Progress()
    out = synth_dataset(
        args.out,
        args.n,
        args.seed,
        lambda i, n: bar(i, n, "rendering "),
        structured_light=args.sensor == "structured-light",
    )
    bar.done()
    return run_info(argparse.Namespace(dataset=out))


def run_import_csv(args: argparse.Namespace) -> int:
    camera = read_camera(args.camera) if args.camera else None
    out = import_csv_dataset(
        args.folder, args.csv, args.out, camera, origin=0 if args.zero_based else 1
    )
    return run_info(argparse.Namespace(dataset=out))


def run_info(args: argparse.Namespace) -> int:
    ds = load_dataset(args.dataset)
    c = ds.camera
    print(
        f"{ds.root}: {len(ds.images)} images {c.width}x{c.height} (fx {c.fx:.1f}), "
        f"{ds.n_holes} access holes, {ds.n_crowd} partly in view (crowd), "
        f"{sum(1 for im in ds.images if not im.boxes)} images without a hole"
    )
    return 0
