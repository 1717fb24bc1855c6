"""``holescan ground`` through a real TAK server (taky) on loopback, over TCP and TLS.

The station publishes with pytak to taky; a second pytak client connected to the same
server receives each hole, its update and its withdrawal, as a TAK device would. Over TLS
both clients present certificates the test made (the station a ``.p12``, the reader a PEM
pair) and a stranger's certificate is refused. TLS settings that cannot work are one line
at start (:func:`tak_settings`, the CLI).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

import pytest
from takserver import (
    P12_PASSWORD,
    Pki,
    TakClient,
    Taky,
    free_tcp_port,
    make_pki,
    p12_settings,
)
from test_station import hole, picture, wait_for

from holescan import cli
from holescan.ground import CotError, GroundHole, GroundOptions, GroundStation, TakTls
from holescan.ground.station import DATAPACKAGE_NAME, tak_settings
from holescan.ground.station.records import FORMAT
from holescan.missions import HoleMissionServer
from tests._support import free_udp_port

UID = "holescan-ground-hole-1"


def cot_time(text: str | None) -> dt.datetime:
    assert text is not None
    return dt.datetime.strptime(text, "%Y-%m-%dT%H:%M:%S.%fZ").replace(tzinfo=dt.UTC)


def point(ev: ET.Element) -> dict[str, float]:
    p = ev.find("point")
    assert p is not None
    return {k: float(v) for k, v in p.attrib.items()}


def remarks(ev: ET.Element) -> str:
    return ev.findtext("detail/remarks") or ""


def check_withdrawal(reader: TakClient) -> None:
    """The rejected hole's stale-now event and the TAK delete naming it."""
    stale = [e for e in reader.of(UID) if e.get("stale") == e.get("time")]
    assert stale, "no stale-now event"
    (delete,) = reader.of(f"{UID}-delete")
    assert delete.get("type") == "t-x-d-d"
    link = delete.find("detail/link")
    assert link is not None and link.get("uid") == UID
    assert delete.find("detail/__forcedelete") is not None


def test_holes_through_taky_over_tcp(tmp_path: Path) -> None:
    """Vehicle (MAVLink) -> station -> taky (TCP) -> a second TAK client."""
    port = free_udp_port()
    with Taky(tmp_path / "taky") as server, TakClient(server.url) as reader:
        opts = GroundOptions(
            mavlink=f"udpin:127.0.0.1:{port}",
            out=tmp_path / "station",
            http_port=None,
            cot_url=server.url,
            cot_stale_s=900.0,
        )
        with (
            GroundStation(opts) as station,
            HoleMissionServer(f"udpout:127.0.0.1:{port}", 1) as vehicle,
        ):
            h = hole(1)
            vehicle.update_holes([h])
            link = station.link
            assert link is not None  # a STATUSTEXT is sent once: to a link that hears us
            wait_for(lambda: bool(link.peers), 30.0, "the station hearing the vehicle")
            vehicle.announce(h)
            wait_for(lambda: reader.of(UID), 30.0, "hole 1 through taky")
            first = reader.of(UID)[0]
            assert point(first)["lat"] == pytest.approx(h.lat_deg, abs=1e-6)  # taky: 6 places
            # the update: the vehicle moved the hole and sent its card (picture, sigma)
            moved = dataclasses.replace(h, lat_deg=h.lat_deg + 2e-5)
            vehicle.update_holes([moved])
            vehicle.announce(moved)
            vehicle.send_card(moved, picture(1), "score 0.88: 1.10 x 0.70 m opening")

            def updated() -> bool:
                return any(
                    abs(point(e)["lat"] - moved.lat_deg) < 2e-6 and point(e)["ce"] < 100
                    for e in reader.of(UID)
                )

            wait_for(updated, 60.0, "the moved hole with its card's facts")
            station.mark(1, "rejected")
            wait_for(lambda: reader.of(f"{UID}-delete"), 10.0, "the withdrawal")
    update = next(
        e for e in reader.of(UID) if point(e)["ce"] < 100 and e.get("stale") != e.get("time")
    )
    # the 95 % circle; taky re-prints ce with one decimal
    assert point(update)["ce"] == pytest.approx(1.6215 * 0.3, abs=0.06)
    assert remarks(update).startswith("ANNOUNCED: hole 1")
    assert "first seen" in remarks(update)
    tier = update.find("detail/holescan")
    assert tier is not None and tier.get("tier") == "announced"
    for e in (first, update):  # stale from the moment it was sent
        assert cot_time(e.get("stale")) - cot_time(e.get("time")) == dt.timedelta(seconds=900)
    check_withdrawal(reader)


def test_station_reconnects_when_the_server_restarts(tmp_path: Path) -> None:
    """The server goes away and comes back on the same port: the station reconnects, sends
    again what the new server has not seen (hole 1) and the hole that came meanwhile."""
    port = free_tcp_port()
    opts = GroundOptions(
        mavlink=f"udpin:127.0.0.1:{free_udp_port()}",
        out=tmp_path / "station",
        http_port=None,
        cot_url=f"tcp://127.0.0.1:{port}",
    )
    with GroundStation(opts) as station:
        with Taky(tmp_path / "taky1", port=port) as first, TakClient(first.url) as reader:
            station.state.on_statustext(f"HOLE 1 0.88 {hole(1).lat_deg:.7f} -79.3831900")
            wait_for(lambda: reader.of(UID), 30.0, "hole 1 through the first server")
        # the first server is gone; hole 2 comes while it is down
        station.state.on_statustext(f"HOLE 2 0.77 {hole(2).lat_deg:.7f} -79.3831800")
        with Taky(tmp_path / "taky2", port=port) as second, TakClient(second.url) as again:
            uids = {UID, "holescan-ground-hole-2"}
            wait_for(
                lambda: uids <= {e.get("uid") for e in again.events},
                30.0,
                "holes 1 and 2 through the second server",
            )
        assert station.cot is not None and station.cot.connects >= 2


def test_review_holes_reach_tak_only_once_confirmed(tmp_path: Path) -> None:
    """A hole the vehicle sent for review is not on TAK (nor in the data package) until an
    operator confirms it; set back to the vehicle's word it is withdrawn again."""
    out = tmp_path / "station"
    out.mkdir()
    holes = [
        GroundHole(1, hole(1).lat_deg, -79.38319, 0.95, t_first_unix_ns=1),
        GroundHole(2, hole(2).lat_deg, -79.38318, 0.6, vehicle_tier="review", t_first_unix_ns=1),
    ]
    doc = {"format": FORMAT, "version": 1, "holes": [h.to_json() for h in holes], "track": []}
    (out / "station.json").write_text(json.dumps(doc))  # a station resumed with both holes
    review = "holescan-ground-hole-2"
    with Taky(tmp_path / "taky") as server, TakClient(server.url) as reader:
        opts = GroundOptions(
            mavlink=f"udpin:127.0.0.1:{free_udp_port()}",
            out=out,
            http_port=None,
            cot_url=server.url,
        )
        with GroundStation(opts) as station:
            wait_for(lambda: reader.of(UID), 30.0, "the announced hole")
            assert not reader.of(review)
            assert package_uids(out) == {UID}
            station.mark(2, "confirmed")
            wait_for(lambda: reader.of(review), 30.0, "the confirmed review hole")
            assert package_uids(out) == {UID, review}
            station.mark(2, "new")  # the operator takes it back: the vehicle's "review"
            wait_for(lambda: reader.of(f"{review}-delete"), 30.0, "its withdrawal")
            assert package_uids(out) == {UID}
    (sent,) = [e for e in reader.of(review) if e.get("stale") != e.get("time")]
    assert remarks(sent).startswith("CONFIRMED: hole 2")
    assert not reader.of(f"{UID}-delete")


def package_uids(folder: Path) -> set[str]:
    with zipfile.ZipFile(folder / DATAPACKAGE_NAME) as z:
        return {n.split("/")[0] for n in z.namelist() if n.endswith(".cot")}


@pytest.fixture
def pki(tmp_path: Path) -> Pki:
    return make_pki(tmp_path / "pki")


def test_holes_through_taky_over_tls_with_client_certificates(tmp_path: Path, pki: Pki) -> None:
    """Station (.p12) -> taky (TLS, client certificates required) -> a reader (PEM);
    re-sends carry a new stale time each; a stranger's certificate is refused."""
    with Taky(tmp_path / "taky", pki) as server:
        cert, key = pki.pem["reader"]
        pem = {
            "PYTAK_TLS_CLIENT_CERT": str(cert),
            "PYTAK_TLS_CLIENT_KEY": str(key),
            "PYTAK_TLS_CLIENT_CAFILE": str(pki.ca),
        }
        with TakClient(server.url, pem) as reader:
            tls = TakTls(pki.p12["station"], ca=pki.ca, password=P12_PASSWORD)
            opts = GroundOptions(
                mavlink=f"udpin:127.0.0.1:{free_udp_port()}",
                out=tmp_path / "station",
                http_port=None,
                cot_url=server.url,
                cot_tls=tls,
                cot_stale_s=120.0,
                cot_refresh_s=1.0,
            )
            with GroundStation(opts) as station:
                station.state.on_statustext(f"HOLE 1 0.88 {hole(1).lat_deg:.7f} -79.3831900")
                wait_for(lambda: reader.of(UID), 30.0, "hole 1 through taky over TLS")
                facts = {"id": 1, "rev": 1, "lat": hole(1).lat_deg, "lon": -79.38319}
                facts |= {"score": 0.88, "sigma": 0.4, "alt": 121.0, "n": 5}
                station.state.on_card(facts, picture(1))
                wait_for(
                    lambda: any(point(e)["ce"] < 100 for e in reader.of(UID)),
                    30.0,
                    "the card's update",
                )
                station.mark(1, "confirmed")
                wait_for(
                    lambda: sum(remarks(e).startswith("CONFIRMED") for e in reader.of(UID)) >= 2,
                    30.0,
                    "the confirmed hole, re-sent by the refresh",
                )
                station.mark(1, "rejected")
                wait_for(lambda: reader.of(f"{UID}-delete"), 10.0, "the withdrawal over TLS")
            stranger = TakClient(
                server.url,
                p12_settings(pki, "reader") | {"PYTAK_TLS_CLIENT_CERT": str(pki.stranger_p12)},
                name="stranger",
            )
            with pytest.raises(AssertionError, match="stranger"):
                stranger.__enter__()
            stranger.__exit__()
    confirmed = [e for e in reader.of(UID) if remarks(e).startswith("CONFIRMED")]
    assert point(confirmed[0])["ce"] == pytest.approx(1.6215 * 0.4, abs=0.06)
    assert point(confirmed[0])["hae"] == pytest.approx(121.0)
    holescan = confirmed[0].find("detail/holescan")
    assert holescan is not None and holescan.get("tier") == "confirmed"
    assert holescan.get("sigma_h_m") == "0.400"
    stales = [cot_time(e.get("stale")) for e in confirmed[:2]]
    times = [cot_time(e.get("time")) for e in confirmed[:2]]
    assert stales[1] > stales[0]  # the re-send's stale counts from its own sending
    for s, t in zip(stales, times, strict=True):
        assert s - t == dt.timedelta(seconds=120)
    check_withdrawal(reader)


def test_tls_by_address_to_a_server_named_in_its_certificate(tmp_path: Path) -> None:
    """The server's certificate names only ``takserver.test`` (no IP address): the station
    connecting to 127.0.0.1 verifies it against --tak-server-name."""
    pki = make_pki(tmp_path / "pki", server_names=("takserver.test",))
    with (
        Taky(tmp_path / "taky", pki) as server,
        TakClient(
            server.url, p12_settings(pki, "reader") | {"PYTAK_TLS_DONT_CHECK_HOSTNAME": "1"}
        ) as reader,
    ):
        tls = TakTls(pki.p12["station"], ca=pki.ca, password=P12_PASSWORD)
        opts = GroundOptions(
            mavlink=f"udpin:127.0.0.1:{free_udp_port()}",
            out=tmp_path / "station",
            http_port=None,
            cot_url=server.url,
            cot_tls=dataclasses.replace(tls, server_name="takserver.test"),
        )
        with GroundStation(opts) as station:
            station.state.on_statustext(f"HOLE 1 0.88 {hole(1).lat_deg:.7f} -79.3831900")
            wait_for(lambda: reader.of(UID), 30.0, "hole 1, the server verified by name")


def test_a_refused_certificate_is_said(
    tmp_path: Path, pki: Pki, caplog: pytest.LogCaptureFixture
) -> None:
    """The server refuses the station's certificate (another CA signed it): the station
    says why in one log line at once, and keeps retrying."""
    with Taky(tmp_path / "taky", pki) as server:
        tls = TakTls(pki.stranger_p12, ca=pki.ca, password=P12_PASSWORD)
        opts = GroundOptions(
            mavlink=f"udpin:127.0.0.1:{free_udp_port()}",
            out=tmp_path / "station",
            http_port=None,
            cot_url=server.url,
            cot_tls=tls,
        )
        with (
            caplog.at_level("WARNING", logger="holescan.ground.station.tak"),
            GroundStation(opts) as station,
        ):
            station.state.on_statustext(f"HOLE 1 0.88 {hole(1).lat_deg:.7f} -79.3831900")
            # the alert comes with the stream's end or with the next write: either says it
            wait_for(lambda: "UNKNOWN_CA" in caplog.text, 30.0, "the server's refusal, in the log")


# -- TLS settings that cannot work: one line at start -------------------------------------
def test_tls_settings_checked_at_start(tmp_path: Path, pki: Pki) -> None:
    url = "tls://127.0.0.1:8089"
    ok = tak_settings(url, TakTls(pki.p12["station"], ca=pki.ca, password=P12_PASSWORD))
    assert ok["PYTAK_TLS_CLIENT_CERT"] == str(pki.p12["station"])
    cert, key = pki.pem["station"]
    assert tak_settings(url, TakTls(cert, key, pki.ca))["PYTAK_TLS_CLIENT_KEY"] == str(key)
    other_cert, other_key = pki.pem["reader"]
    bad = {
        "missing .p12": (TakTls(tmp_path / "nope.p12", password="x"), "nope.p12"),
        "wrong password": (TakTls(pki.p12["station"], password="wrong"), "password is wrong"),
        "no password": (TakTls(pki.p12["station"]), "--tak-password-file"),
        "PEM without key": (TakTls(cert), "--tak-key"),
        "key of another": (TakTls(cert, other_key), "not a PEM certificate and its key"),
        "missing CA": (TakTls(other_cert, other_key, tmp_path / "ca.pem"), "ca.pem"),
    }
    (tmp_path / "garbage.p12").write_bytes(b"not a pkcs12 file")
    bad["garbage"] = (TakTls(tmp_path / "garbage.p12", password="x"), "not a PKCS#12")
    for why, (tls, says) in bad.items():
        with pytest.raises(CotError, match=says.replace(".", r"\.")) as err:
            tak_settings(url, tls)
        assert "\n" not in str(err.value), why
    for wrong_url, says in {
        "tcp://127.0.0.1:8087": "for tls:// URLs",
        "http://127.0.0.1:8087": "udp\\+wo",
        "tcp://127.0.0.1": "needs a host and a port",
    }.items():
        with pytest.raises(CotError, match=says):
            tak_settings(wrong_url, TakTls(cert, key) if "for tls" in says else None)
    with pytest.raises(CotError, match="--tak-cert"):
        tak_settings(url, None)


def test_cli_bad_certificate_is_one_line(
    tmp_path: Path, pki: Pki, capsys: pytest.CaptureFixture[str]
) -> None:
    pw = tmp_path / "pw"
    pw.write_text("wrong\n")
    base = ["ground", "--mavlink", "udpin:127.0.0.1:1", "--http", "off"]
    cases = {
        "missing": ["--tak-cert", str(tmp_path / "missing.p12"), "--tak-password-file", str(pw)],
        "password": ["--tak-cert", str(pki.p12["station"]), "--tak-password-file", str(pw)],
        "no password file": [
            "--tak-cert",
            str(pki.p12["station"]),
            "--tak-password-file",
            str(tmp_path / "nopw"),
        ],
        "key alone": ["--tak-key", str(pki.pem["station"][1])],
    }
    for i, (why, extra) in enumerate(cases.items()):
        out = tmp_path / f"st{i}"
        rc = cli.main([*base, "-o", str(out), "--cot", "tls://127.0.0.1:8089", *extra])
        err = capsys.readouterr().err.strip()
        assert rc == 2, why
        assert err.startswith("holescan ground: error:") and "\n" not in err, (why, err)
        assert not out.exists(), why  # nothing created for options that cannot work
    rc = cli.main([*base, "-o", str(tmp_path / "s"), "--cot-refresh", "7200"])
    assert rc == 2 and "stale" in capsys.readouterr().err
    rc = cli.main([*base, "-o", str(tmp_path / "p"), "--cot", "tcp://h:8087", "--cot-proto", "1"])
    assert rc == 2 and "mesh udp:// only" in capsys.readouterr().err
