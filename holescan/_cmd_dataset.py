"""``holescan dataset synth|info``: make and inspect COCO-style RGB-D hole datasets."""

from __future__ import annotations

import argparse
from pathlib import Path

from capture import check_folder
from ground import load_dataset
from holescan._args import Progress


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("dataset", help="make or inspect an RGB-D hole dataset")
    verbs = p.add_subparsers(dest="dataset_verb", required=True, metavar="ACTION")
    s = verbs.add_parser("synth", help="render a synthetic rubble dataset with ground truth")
    s.add_argument("out", type=Path, help="output folder")
    s.add_argument("--n", type=int, default=60, help="number of images (default 60)")
    s.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    s.set_defaults(func=run_synth)
    i = verbs.add_parser("info", help="count images and holes of a dataset")
    i.add_argument("dataset", type=Path)
    i.set_defaults(func=run_info)


def run_synth(args: argparse.Namespace) -> int:
    from sim import synth_dataset

    existing = args.out.absolute()
    while not existing.exists():  # the folders synth would create must be creatable
        existing = existing.parent
    check_folder(existing)
    bar = Progress()
    out = synth_dataset(args.out, args.n, args.seed, lambda i, n: bar(i, n, "rendering "))
    bar.done()
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
