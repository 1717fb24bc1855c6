"""The figures of a finished ``sitl_sortie.py`` run: what reached the GCS against the
simulated world's truth, the clocks against SITL's, poses against SITL's own state, frames and
bytes (``sitl_sortie.py --report-only`` prints them again)."""

from __future__ import annotations

import bisect
import json
import math
import re
import statistics
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from holescan.geotag import local_en_m  # noqa: E402
from holescan.link import mavutil  # noqa: E402

RADIO_BYTES_PER_S = 57_600 / 10  # 8N1: 10 bits a byte


Truth = list[tuple[int, float, float, float, float, float]]
"""SITL's own state: (arrival mono ns, lat, lon, roll, pitch, yaw) per SIMSTATE/SIM_STATE."""


def median_or_nan(v: list[float]) -> float:
    return statistics.median(v) if v else math.nan


def p95(v: list[float]) -> float:
    return sorted(v)[min(len(v) - 1, int(0.95 * len(v)))] if v else math.nan


class SitlClock:
    """SITL's boot clock minus the host's monotonic one near a time, from the controller's
    quickest TIMESYNC round trips within 5 s (SITL's clock does not keep to the host's
    exactly when the host is loaded: a local estimate, not one offset for the run)."""

    def __init__(self, samples: list[list[int]]) -> None:
        self.samples = sorted((int(t), int(rt), int(o)) for t, rt, o in samples)
        self.times = [s[0] for s in self.samples]

    def offset(self, t_mono_ns: float) -> float:
        lo = bisect.bisect_left(self.times, t_mono_ns - 5e9)
        hi = bisect.bisect_right(self.times, t_mono_ns + 5e9)
        near = sorted(self.samples[lo:hi], key=lambda s: s[1])[:3] or [
            min(self.samples, key=lambda s: abs(s[0] - t_mono_ns))
        ]
        return float(statistics.median(s[2] for s in near))


def truth_at(truth: Truth, times: list[float], t_boot_ns: int) -> tuple[float, ...] | None:
    """SITL's state at a boot time (``times``: the samples' arrivals on SITL's clock; linear
    between samples)."""
    i = bisect.bisect_left(times, t_boot_ns)
    if i == 0 or i == len(times) or times[i] - times[i - 1] > 200e6:
        return None
    a, b = truth[i - 1], truth[i]
    f = (t_boot_ns - times[i - 1]) / (times[i] - times[i - 1])
    yaw = a[5] + f * math.remainder(b[5] - a[5], math.tau)
    return (*(a[k] + f * (b[k] - a[k]) for k in range(1, 5)), yaw)


def read_wpl(path: Path) -> list[tuple[float, float]]:
    out = []
    for line in path.read_text().splitlines()[1:]:
        f = line.split("\t")
        if len(f) >= 12 and f[0] != "0":
            out.append((float(f[8]), float(f[9])))
    return out


def reboot_report(out: Path, t_reboot_mono_ns: int) -> None:
    """What the companion saw of ArduPilot's reboot: from its log and its flight log."""
    sys.path.insert(0, str(REPO))
    from holescan.flightlog import LoggedFrame, LoggedHealth, read_flight_log

    text = (out / "companion.log").read_text(errors="replace")
    for line in text.splitlines():
        if re.search(r"reboot|went back|rates|clock|silent|heartbeat", line, re.I):
            print("  companion:", line[:160])
    files = sorted((out / "logs").rglob("*.mcap"))
    frames = [  # (capture time, pose's boot time or None); not the images (memory)
        (r.frame.t_mono_ns, r.pose.t_boot_ns if r.pose else None)
        for r in read_flight_log(files, kinds={LoggedFrame})
        if isinstance(r, LoggedFrame)
    ]
    after = [f for f in frames if f[0] > t_reboot_mono_ns]
    posed = [f for f in after if f[1] is not None]
    first = (posed[0][0] - t_reboot_mono_ns) / 1e9 if posed else float("nan")
    before = [b for t, b in frames if b is not None and t < t_reboot_mono_ns]
    boots = [b for _, b in posed if b is not None]
    print(
        f"frames {len(frames)}, after the reboot {len(after)}, posed {len(posed)}; first posed "
        f"{first:.1f} s after the command; boot time of poses before <= "
        f"{max(before, default=0) / 1e9:.1f} s, after from {min(boots, default=0) / 1e9:.1f} s"
    )
    health = [r.values for r in read_flight_log(files, kinds={LoggedHealth})]
    last = [h for h in health if "clock_source" in h]
    if last:
        keys = ("clock_source", "autopilot_mode", "autopilot_armed", "pose_refusals")
        print("last health:", {k: last[-1].get(k) for k in keys})


def report(out: Path, truth: Any) -> None:
    """Print the figures of a finished run in ``out`` (its logs, tlog, controller.json)."""
    from holescan.flightlog import LoggedFrame, LoggedHealth, LoggedHoles, read_flight_log

    saved = json.loads((out / "controller.json").read_text())
    rows, t_survey = saved["truth"], saved["t_survey"]
    clock = SitlClock(saved["timesync"])
    dl = out / "holes_at_gcs.txt"
    files = sorted((out / "logs").glob("flight-*_*.mcap"))
    records = list(read_flight_log(files))
    # What the GCS downloaded, against the truth (0.5 m, as format_sim_report counts).
    got = read_wpl(dl) if dl.is_file() else []
    print(f"GCS downloaded {len(got)} holes (component 191 through ArduPilot's routing)")
    used: set[int] = set()
    errors = []
    for t in truth:
        near = sorted(
            (math.hypot(*local_en_m(la, lo, t.lat_deg, t.lon_deg)), i)
            for i, (la, lo) in enumerate(got)
            if i not in used
        )
        if near and near[0][0] <= 0.5:
            used.add(near[0][1])
            errors.append(near[0][0])
    print(
        f"truth {len(truth)} access holes: found {len(errors)}, missed {len(truth) - len(errors)},"
        f" false {len(got) - len(used)}; position error median {median_or_nan(errors):.2f} m, "
        f"max {max(errors, default=math.nan):.2f} m"
    )
    # First sighting (autopilot boot clock -> host) -> STATUSTEXT at MAVProxy (its tlog).
    first: dict[int, int] = {}
    for r in records:
        if isinstance(r, LoggedHoles):
            for h in r.holes:
                first.setdefault(int(h["id"]), int(h["t_first_boot_ns"]))
    unix_minus_mono = saved["unix_minus_mono"]
    at_gcs: dict[int, float] = {}
    card_bytes = ap_bytes = 0
    t_lo = t_hi = None
    tl = mavutil.mavlink_connection(str(out / "gcs.tlog"))
    while (m := tl.recv_match()) is not None:
        ts = m._timestamp
        t_lo = ts if t_lo is None else t_lo
        t_hi = ts
        if m.get_type() == "STATUSTEXT" and (g := re.match(r"HOLE (\d+) ", m.text)):
            at_gcs.setdefault(int(g.group(1)), ts)
        if m.get_type() in ("ENCAPSULATED_DATA", "DATA_TRANSMISSION_HANDSHAKE"):
            card_bytes += len(m.get_msgbuf())
        elif m.get_srcComponent() == 1:
            ap_bytes += len(m.get_msgbuf())
    g = clock.samples[0][2]  # boot -> mono: a first guess, then the local offset there
    lat = [
        at_gcs[i] - (first[i] - clock.offset(first[i] - g) + unix_minus_mono) / 1e9
        for i in at_gcs
        if i in first
    ]
    print(
        f"first sighting -> STATUSTEXT at the GCS: median {median_or_nan(lat):.2f} s, max "
        f"{max(lat, default=math.nan):.2f} s over {len(lat)} holes"
    )
    span = (t_hi - t_lo) if t_lo is not None and t_hi is not None else math.nan
    print(
        f"at the GCS over {span:.0f} s: ArduPilot's own telemetry {ap_bytes / span:.0f} B/s, "
        f"pictures {card_bytes / span:.0f} B/s; a 57,600-baud radio carries "
        f"{RADIO_BYTES_PER_S:.0f} B/s, leaving {RADIO_BYTES_PER_S - ap_bytes / span:.0f} B/s"
    )
    # The companion's clock against SITL's (the controller's quickest round trips).
    rtts = [rt / 1e6 for _, rt, _ in clock.samples]
    est = [
        float(r.values["clock_offset_ns"]) - clock.offset(r.t_unix_ns - unix_minus_mono)
        for r in records
        if isinstance(r, LoggedHealth) and "clock_offset_ns" in r.values
    ]
    print(
        f"TIMESYNC on the controller link: round trip median {median_or_nan(rtts):.2f} ms, p95 "
        f"{p95(rtts):.2f} ms; companion's boot-clock offset vs SITL: median "
        f"{median_or_nan(est) / 1e6:+.2f} ms, jitter (std) "
        f"{(statistics.pstdev(est) if len(est) > 1 else math.nan) / 1e6:.2f} ms over {len(est)} s"
    )
    # The pose at frame time against SITL's own truth.
    h_err, att_err = [], []
    truth_boot = [row[0] + clock.offset(row[0]) for row in rows]
    frames = [r for r in records if isinstance(r, LoggedFrame)]
    for f in frames:
        if f.pose is None or f.t_boot_ns is None:
            continue
        tr = truth_at(rows, truth_boot, f.t_boot_ns)
        if tr is None:
            continue
        h_err.append(math.hypot(*local_en_m(f.pose.lat_deg, f.pose.lon_deg, tr[0], tr[1])))
        att_err.append(
            math.degrees(
                max(
                    abs(f.pose.roll - tr[2]),
                    abs(f.pose.pitch - tr[3]),
                    abs(math.remainder(f.pose.yaw - tr[4], math.tau)),
                )
            )
        )
    print(
        f"pose at frame time vs SIMSTATE over {len(h_err)} frames: horizontal median "
        f"{median_or_nan(h_err):.3f} m, p95 {p95(h_err):.3f} m; attitude (worst axis) median "
        f"{median_or_nan(att_err):.2f} deg, p95 {p95(att_err):.2f} deg"
    )
    comp_out = (out / "companion.log").read_text()
    for line in comp_out.splitlines():
        if line.startswith(("frames:", "detector:", "sim:", "holes:", "telemetry:")):
            print(f"companion {line}")
    print(f"survey {t_survey:.0f} s in AUTO; logs in {out}")
