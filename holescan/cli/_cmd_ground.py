"""``holescan ground``: the ground station app (holes -> live page, TAK, map files)."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from types import FrameType


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "ground",
        help="ground station: collect the vehicle's holes, live map page, TAK, KML/GeoJSON/GPX",
        description="Run beside QGroundControl / Mission Planner on the vehicle's MAVLink "
        "stream (e.g. MAVProxy --out udpout:127.0.0.1:14551, then --mavlink "
        "udpin:0.0.0.0:14551). Collects every announced hole (STATUSTEXT, its picture and "
        "facts, the hole mission of component 191) into DIR/station.json, serves a live map "
        "page, publishes the holes to TAK as Cursor-on-Target, and keeps holes.kml, "
        "holes_live.kml (Google Earth), holes.geojson (CalTopo) and holes.gpx current. "
        "Ctrl-C stops it; a restart resumes from DIR.",
    )
    p.add_argument(
        "--mavlink",
        required=True,
        action="append",
        help="the vehicles' stream: udpin:0.0.0.0:PORT, udpout:HOST:PORT, tcp:HOST:PORT, "
        "or a serial device; repeat for several links (every vehicle heard on any of them "
        "is followed, their holes merged into one id per opening)",
    )
    p.add_argument("--baud", type=int, default=57600, help="serial links only (default 57600)")
    p.add_argument("-o", "--out", type=Path, required=True, help="station folder")
    p.add_argument(
        "--sysid",
        type=int,
        help="follow this vehicle's system id only (default: every vehicle heard)",
    )
    p.add_argument(
        "--http",
        default="127.0.0.1:8080",
        help="live page HOST:PORT, or 'off' (0.0.0.0:PORT: every network of the laptop; "
        "marking always needs an operator's pairing, see --pair)",
    )
    p.add_argument(
        "--pair",
        action="append",
        default=[],
        metavar="NAME",
        help="issue a pairing link for operator NAME at start (repeatable), shown once on "
        "the terminal and never logged; marks are recorded under it. Without any, a "
        "folder with no pairing yet gets one for 'operator 1'. More while it runs: "
        "holescan pair",
    )
    p.add_argument(
        "--http-name",
        action="append",
        default=None,
        metavar="NAME",
        help="a host name the page is opened by besides its IP addresses (repeatable; "
        "default: this machine's hostname and HOSTNAME.local); other names are refused",
    )
    p.add_argument(
        "--basemap",
        action="append",
        default=[],
        type=Path,
        metavar="FILE",
        help="an offline basemap for the live page (repeatable, switchable there): raster "
        "tiles in an MBTiles file (.mbtiles), or a GeoTIFF (.tif) such as an earlier sortie's "
        "or campaign's NAME_ortho.tif",
    )
    p.add_argument(
        "--public-url",
        metavar="URL",
        help="the station's address as the team's handhelds and laptops reach it, "
        "http://ADDRESS:PORT (e.g. http://192.168.1.10:8080): the picture links in CoT and "
        "in the live layers /holes.geojson, /holes.kml (default: the address of --http; "
        "with 0.0.0.0, the laptop's primary address)",
    )
    p.add_argument(
        "--cot",
        default="udp+wo://239.2.3.1:6969",
        help="TAK: mesh multicast udp+wo://239.2.3.1:6969 (default), a TAK server "
        "tcp://HOST:8087 or tls://HOST:8089 (with --tak-cert), or 'off'",
    )
    p.add_argument(
        "--tak-cert",
        type=Path,
        help="tls:// only: the client certificate, a .p12 (with --tak-password-file) or a "
        "PEM certificate (with --tak-key)",
    )
    p.add_argument("--tak-key", type=Path, help="the PEM client certificate's key")
    p.add_argument(
        "--tak-password-file",
        type=Path,
        help="a file holding the .p12's password (TAK servers' default is atakatak)",
    )
    p.add_argument(
        "--tak-ca", type=Path, help="the CA (PEM) that signed the TAK server's certificate"
    )
    p.add_argument(
        "--tak-server-name",
        help="the name in the server's certificate, when --cot has its IP address",
    )
    p.add_argument(
        "--cot-stale",
        type=float,
        default=3600.0,
        metavar="S",
        help="each CoT event goes stale S seconds after it is sent (default 3600)",
    )
    p.add_argument(
        "--cot-refresh",
        type=float,
        default=600.0,
        metavar="S",
        help="every hole is sent again every S seconds, below --cot-stale (default 600)",
    )
    p.add_argument(
        "--overlay",
        type=Path,
        help="a map overlay (.kmz) to put in holes_datapackage.zip with the holes",
    )
    p.add_argument(
        "--cot-proto",
        type=int,
        choices=(0, 1),
        default=0,
        help="0: CoT XML (default), 1: TAK protocol v1 protobuf (mesh only; needs takproto)",
    )
    p.add_argument("--station", default="ground", help="name used in the CoT uids")
    key = p.add_mutually_exclusive_group()
    key.add_argument(
        "--mavlink-key-file",
        type=Path,
        metavar="FILE",
        help="MAVLink 2 signing: a file of one line, the key as 64 hex digits or a "
        "passphrase (as MAVProxy's 'signing key PASSPHRASE'); the vehicle's fly.toml "
        "mavlink_key/mavlink_key_file holds the same. Unsigned packets are then dropped",
    )
    key.add_argument(
        "--mavlink-key",
        metavar="HEX",
        help="the signing key as 64 hex digits (visible to other users in 'ps': prefer "
        "--mavlink-key-file)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from holescan.errors import InputError
    from holescan.ground import GroundOptions, TakTls, run_ground
    from holescan.link import SigningKey

    host, port = "127.0.0.1", None
    if args.http != "off":
        host, _, port_text = args.http.rpartition(":")
        try:
            port = int(port_text)
        except ValueError as err:
            raise InputError(f"--http wants HOST:PORT or 'off', got {args.http!r}") from err
    tls = None
    if args.tak_cert is not None:
        password = None
        if args.tak_password_file is not None:
            try:
                password = args.tak_password_file.read_text().rstrip("\r\n")
            except OSError as err:
                raise InputError(
                    f"--tak-password-file {args.tak_password_file}: {err.strerror or err}"
                ) from err
        tls = TakTls(args.tak_cert, args.tak_key, args.tak_ca, password, args.tak_server_name)
    elif any(
        v is not None
        for v in (args.tak_key, args.tak_ca, args.tak_password_file, args.tak_server_name)
    ):
        raise InputError("--tak-key, --tak-ca, --tak-password-file go with --tak-cert")
    opts = GroundOptions(
        mavlink=args.mavlink[0],
        more_mavlink=tuple(args.mavlink[1:]),
        out=args.out,
        sysid=args.sysid,
        baud=args.baud,
        http_host=host or "127.0.0.1",
        http_port=port,
        http_names=None if args.http_name is None else tuple(args.http_name),
        cot_url=None if args.cot == "off" else args.cot,
        cot_proto=args.cot_proto,
        cot_tls=tls,
        station=args.station,
        cot_stale_s=args.cot_stale,
        cot_refresh_s=args.cot_refresh,
        overlay=args.overlay,
        pair=tuple(args.pair),
        public_url=args.public_url,
        basemaps=tuple(args.basemap),
        signing=(
            SigningKey.from_file(args.mavlink_key_file)
            if args.mavlink_key_file is not None
            else SigningKey.from_hex(args.mavlink_key)
            if args.mavlink_key is not None
            else None
        ),
    )
    stop = threading.Event()

    def on_signal(signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    run_ground(opts, stop, show_on_terminal())
    return 0


def show_on_terminal() -> Callable[[str], None] | None:
    """Lines for the operator's eyes only: to the terminal, never to a log (None when
    stderr is not a terminal, e.g. under systemd, whose journal is a log)."""
    if not sys.stderr.isatty():
        return None
    return lambda line: print(line, file=sys.stderr, flush=True)
