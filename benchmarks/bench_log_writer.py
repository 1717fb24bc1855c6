"""The MCAP flight log writer at 30 fps, and the image codecs it can store frames with.

Two parts, medians over repeated runs (docs/flight-log.md has the figures):

* ``--codecs``: bytes and encoding time per VGA image of every candidate codec, on
  simulated frames (rendered rubble, the sensor model's noise and dropouts) and, with
  ``--real FOLDER``, on real Kinect-v1 frames (the TUM / NYU / SUN samples that
  ``benchmarks/real_frames.py`` reads). Depth: raw, PNG (OpenCV, level 1 and 3), zstd per
  message (levels 1 and 3, and on split byte planes), lz4, RVL (Wilson 2017, written here in
  numpy for the comparison only) and RVL + zstd. Colour: JPEG q75-95, PNG, zstd.
* the writer (default): VGA RGB-D frames paced like the Xtion's, written by
  :class:`capture.FlightLogWriter` with the image settings given. Per run: the writer
  thread's CPU per frame (image encoding, protobuf, chunk compression) and so the share
  of one core it takes at that rate, its wall time per frame, the longest ``write_frame``
  call on the capture thread, the deepest the frame queue got, drops, and MB/s on disk.

    python benchmarks/bench_log_writer.py [--frames 90] [--repeat 5] [--fps 30]
        [--color jpeg] [--jpeg-quality 90] [--depth zstd] [--compression zstd]
        [--source sim|random|real] [--real FOLDER]
    python benchmarks/bench_log_writer.py --codecs [--real FOLDER]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import lz4.frame
import numpy as np
import numpy.typing as npt
import zstandard

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # this checkout
sys.path.insert(0, str(Path(__file__).resolve().parent))

from holescan.detect import CameraIntrinsics, Frame
from holescan.flightlog import FlightLogWriter, LogOptions

VGA = CameraIntrinsics.xtion()


def random_frames(n: int) -> list[Frame]:
    """The test suite's synthetic VGA frames: random colour (the worst case for every
    codec), a depth ramp with noise and 5 % of pixels without a reading."""
    out = []
    for i in range(n):
        rng = np.random.default_rng(1000 + i)
        _yy, xx = np.mgrid[0 : VGA.height, 0 : VGA.width]
        depth = 1500 + 400 * np.sin((xx + 3 * i) / 9.0) + rng.integers(0, 20, xx.shape)
        depth[rng.random(xx.shape) < 0.05] = 0
        rgb = rng.integers(0, 256, (VGA.height, VGA.width, 3), dtype=np.uint8)
        out.append(Frame(i, rgb, depth.astype(np.uint16), i * 33_333_333, i * 33_366_000))
    return out


def sim_frames(n: int) -> list[Frame]:
    """Rendered rubble frames with the simulated Xtion's noise, dropouts and lighting."""
    from holescan.sim import synth_samples

    samples = synth_samples(n, 3, VGA, images_per_world=4)
    return [Frame(i, s.rgb, s.depth, i * 33_333_333, i * 33_333_333) for i, s in enumerate(samples)]


def real_frames(folder: Path) -> list[Frame]:
    """The real Kinect-v1 sample frames (TUM, NYU, SUN) found in ``folder``."""
    import real_frames as rf

    out = []
    for load in (rf.tum, rf.nyu, rf.sun):
        try:
            rgb, depth, _ = load(folder)
        except (OSError, cv2.error, TypeError, AttributeError):
            continue
        if rgb.shape[:2] != depth.shape:  # NYU raw depth is not registered: same size here
            continue
        out.append(Frame(len(out), rgb, depth.astype(np.uint16), 0, 0))
    if not out:
        raise SystemExit(f"no real frames in {folder}")
    return out


# ------------------------------------------------------------------------------ codecs


def rvl_encode(depth: npt.NDArray[np.uint16]) -> bytes:
    """RVL (Wilson, "Fast Lossless Depth Image Compression", 2017): runs of zeros and of
    non-zeros, zig-zag deltas of the non-zero values, 3-bit variable-length nibbles packed
    eight to a 32-bit word (first nibble in the high bits), as the C reference does."""
    flat = depth.ravel().astype(np.int64)
    nz = flat != 0
    bounds = np.concatenate(([0], np.flatnonzero(np.diff(nz.astype(np.int8))) + 1, [flat.size]))
    lens = np.diff(bounds)
    if nz[0]:
        lens = np.concatenate(([0], lens))  # runs alternate, zeros first
    if len(lens) % 2:
        lens = np.concatenate((lens, [0]))
    zeros, nonzeros = lens[0::2], lens[1::2]
    delta = np.diff(flat[nz], prepend=0)
    zigzag = (delta << 1) ^ (delta >> 63)
    n = 2 * len(zeros) + len(zigzag)
    seq = np.empty(n, np.int64)
    head = np.arange(len(zeros)) * 2 + np.concatenate(([0], np.cumsum(nonzeros)[:-1]))
    seq[head], seq[head + 1] = zeros, nonzeros
    rest = np.ones(n, bool)
    rest[head] = rest[head + 1] = False
    seq[rest] = zigzag
    bits = np.floor(np.log2(np.maximum(seq, 1))).astype(np.int64) + 1
    nibbles = np.maximum(1, (bits + 2) // 3)
    vid = np.repeat(np.arange(n), nibbles)
    pos = np.arange(int(nibbles.sum())) - np.repeat(np.cumsum(nibbles) - nibbles, nibbles)
    nib = ((seq[vid] >> (3 * pos)) & 7) | np.where(pos < nibbles[vid] - 1, 8, 0)
    nib = np.concatenate((nib, np.zeros((-len(nib)) % 8, np.int64))).reshape(-1, 8)
    return (nib << (28 - 4 * np.arange(8))).sum(axis=1).astype("<u4").tobytes()


def _planes(a: npt.NDArray[Any]) -> bytes:
    return np.ascontiguousarray(a.view(np.uint8).reshape(-1, 2).T).tobytes()


def codec_table() -> tuple[dict[str, Callable[[Any], bytes]], dict[str, Callable[[Any], bytes]]]:
    z1, z3 = zstandard.ZstdCompressor(level=1), zstandard.ZstdCompressor(level=3)

    def png(a: Any, level: int) -> bytes:
        return bytes(cv2.imencode(".png", a, [cv2.IMWRITE_PNG_COMPRESSION, level])[1])

    def jpeg(a: Any, q: int) -> bytes:
        bgr = cv2.cvtColor(a, cv2.COLOR_RGB2BGR)
        return bytes(cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, q])[1])

    depth = {
        "raw": lambda a: a.tobytes(),
        "png level 1": lambda a: png(a, 1),
        "png level 3": lambda a: png(a, 3),
        "zstd 1 (chosen)": lambda a: z1.compress(a.tobytes()),
        "zstd 3": lambda a: z3.compress(a.tobytes()),
        "zstd 1, byte planes": lambda a: z1.compress(_planes(a)),
        "lz4": lambda a: lz4.frame.compress(a.tobytes()),
        "rvl (numpy)": rvl_encode,
        "rvl + zstd 1": lambda a: z1.compress(rvl_encode(a)),
    }
    color = {
        "raw": lambda a: a.tobytes(),
        "jpeg q75": lambda a: jpeg(a, 75),
        "jpeg q85": lambda a: jpeg(a, 85),
        "jpeg q90 (chosen)": lambda a: jpeg(a, 90),
        "jpeg q95": lambda a: jpeg(a, 95),
        "png level 1": lambda a: png(cv2.cvtColor(a, cv2.COLOR_RGB2BGR), 1),
        "zstd 1": lambda a: z1.compress(a.tobytes()),
    }
    return depth, color


def bench_codecs(name: str, frames: list[Frame], repeat: int) -> None:
    depth_codecs, color_codecs = codec_table()
    print(f"\n{name}: {len(frames)} VGA frames, medians over frames x {repeat} runs")
    print(f"  {'image':6s} {'codec':22s} {'KB':>7s} {'ms':>7s}")
    for kind, codecs in (("depth", depth_codecs), ("colour", color_codecs)):
        for label, fn in codecs.items():
            sizes, times = [], []
            for f in frames:
                img = f.depth if kind == "depth" else f.rgb
                for _ in range(repeat):
                    t0 = time.perf_counter()
                    data = fn(img)
                    times.append(time.perf_counter() - t0)
                sizes.append(len(data))
            kb, ms = statistics.median(sizes) / 1e3, statistics.median(times) * 1e3
            print(f"  {kind:6s} {label:22s} {kb:7.1f} {ms:7.2f}")


# ------------------------------------------------------------------------------ writer


def run(
    folder: Path, frames: list[Frame], n: int, fps: float, options: LogOptions
) -> dict[str, float]:
    """One paced run of ``n`` frames; what the writer reported."""
    calls = []
    with FlightLogWriter(folder / "bench", VGA, options=options) as w:
        t0 = time.monotonic()
        for i in range(n):
            delay = t0 + i / fps - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            c0 = time.perf_counter()
            w.write_frame(frames[i % len(frames)], time.time_ns())
            calls.append(time.perf_counter() - c0)
    st = w.stats()
    return {
        "frame_cpu_ms_mean": st.frame_cpu_ms_mean,
        "core_share_pct": st.frame_cpu_ms_mean * fps / 10.0,
        "frame_write_ms_mean": st.frame_write_ms_mean,
        "frame_write_ms_max": st.frame_write_ms_max,
        "write_frame_ms_max": 1e3 * max(calls),
        "frames_queued_max": float(st.frames_queued_max),
        "dropped": float(sum(st.dropped.values())),
        "mb_per_frame": st.bytes_written / n / 1e6,
        "mb_per_s": st.bytes_written / n * fps / 1e6,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--frames", type=int, default=90, help="frames per run (default 90: 3 s)")
    ap.add_argument("--repeat", type=int, default=5, help="runs (default 5)")
    ap.add_argument("--fps", type=float, default=30.0, help="capture rate (default 30)")
    ap.add_argument("--color", default="jpeg", choices=["jpeg", "png", "raw"])
    ap.add_argument("--jpeg-quality", type=int, default=90)
    ap.add_argument("--depth", default="zstd", choices=["zstd", "png", "raw"])
    ap.add_argument("--compression", default="zstd", choices=["zstd", "lz4", "none"])
    ap.add_argument("--source", default="sim", choices=["sim", "random", "real"])
    ap.add_argument("--real", type=Path, help="folder of the real sample frames")
    ap.add_argument("--codecs", action="store_true", help="compare the image codecs")
    args = ap.parse_args()
    if args.codecs:
        bench_codecs("simulated frames", sim_frames(16), 3)
        if args.real is not None:
            bench_codecs("real Kinect-v1 frames", real_frames(args.real), 9)
        return
    if args.source == "real":
        if args.real is None:
            raise SystemExit("--source real needs --real FOLDER")
        # 12 distinct frames (each sample shifted sideways): repeating a frame within a
        # chunk would let the chunk compression find the repeat and under-count the bytes
        frames = [
            Frame(k, np.roll(f.rgb, 7 * k, axis=1), np.roll(f.depth, 7 * k, axis=1), 0, 0)
            for k, f in enumerate(real_frames(args.real) * 4)
        ]
    else:
        frames = sim_frames(12) if args.source == "sim" else random_frames(6)
    options = LogOptions(
        color=args.color,
        jpeg_quality=args.jpeg_quality,
        depth=args.depth,
        compression=args.compression,
        image_reserve_bytes=0,
    )
    runs = []
    for k in range(args.repeat):
        with tempfile.TemporaryDirectory() as d:
            runs.append(run(Path(d), frames, args.frames, args.fps, options))
        print(f"run {k + 1}: " + ", ".join(f"{key} {v:.2f}" for key, v in runs[-1].items()))
    med = {key: statistics.median(r[key] for r in runs) for key in runs[0]}
    budget_ms = 1e3 / args.fps
    print(
        f"medians over {args.repeat} runs of {args.frames} {args.source} VGA RGB-D frames at "
        f"{args.fps:g} fps, colour {args.color}"
        + (f" q{args.jpeg_quality}" if args.color == "jpeg" else "")
        + f", depth {args.depth}, chunks {args.compression}: "
        f"writer CPU {med['frame_cpu_ms_mean']:.2f} ms/frame = {med['core_share_pct']:.1f} % "
        f"of one core; wall {med['frame_write_ms_mean']:.1f} ms/frame mean "
        f"({med['frame_write_ms_max']:.1f} ms max; budget {budget_ms:.1f} ms), write_frame "
        f"{med['write_frame_ms_max']:.2f} ms max, queue max {med['frames_queued_max']:.0f} of "
        f"{options.max_queued_frames} frames, {med['dropped']:.0f} dropped, "
        f"{med['mb_per_frame'] * 1e3:.0f} KB/frame = {med['mb_per_s']:.2f} MB/s"
    )
    keeps_up = med["frame_write_ms_mean"] < budget_ms and med["dropped"] == 0
    print(f"keeps up at {args.fps:g} fps: {'yes' if keeps_up else 'NO'}")


if __name__ == "__main__":
    main()
