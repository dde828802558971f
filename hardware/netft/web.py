"""The Net F/T box's web server as programs use it: its XML pages and CGI settings; no sockets.

From ATI's Net F/T manual (9620-05-Net FT, "Common Gateway Interface" and the XML pages) and ATI's
own Net F/T Java demo, which reads them the same way:

- `/netftapi2.xml` is the system setup and the active configuration; `?index=N` shows configuration
  slot N instead (the demo reads `index=0`, takes `setcfgsel`, then reads that slot). Counts per
  force / torque (`cfgcpf`, `cfgcpt`) are integers, as the box writes them; arrays are `;`-separated.
- `/netftcalapi.xml[?index=N]` is stored calibration N (default: the active configuration's):
  serial `calsn`, counts per unit `calcpf` / `calcpt` and their units `scalfu` / `scaltu`.
- CGI pages take `variable=value` pairs in the URL, each variable only on its own page:
  `setting.cgi?setcfgsel=N` selects the active configuration; `comm.cgi?comrdtrate=R` sets the RDT
  output rate (the box rounds it up to a rate it can make: its internal rate over a whole number),
  `comrdtbsiz=B` the records per buffered datagram; `config.cgi?cfgid=N&cfgnam=..&cfgcalsel=C`
  names slot N and picks its calibration.
- `/` answers the box's start page.

Deliberately not modelled, and ignored as the box ignores a variable set on a page that does not
own it: the filter (`setuserfilter`), peak logging, monitor conditions, tool transforms, units
other than the calibration's, network settings and EtherNet/IP. A value out of range is not stored
either. What the box's CGI pages print back is not documented: this answers a short page with
HTTP 200. Ignored assignments are kept in `ignored` (page, variable, value) for tests and logged.
"""

from __future__ import annotations

import html
import logging
import threading
import urllib.parse
from dataclasses import dataclass, replace

from hardware.netft import wire

log = logging.getLogger(__name__)

CONFIGURATION_SLOTS = 16  # setcfgsel 0..15
MAX_RDT_RATE_HZ = 7000  # the box's internal rate (runrate)
MAX_BUFFER_RECORDS = 40  # comrdtbsiz


@dataclass(frozen=True)
class StoredCalibration:
    """One of the box's calibrations: the transducer's serial, counts per unit and units, and the
    sensing ranges (Fx Fy Fz in force units, Tx Ty Tz in torque units) from its calibration sheet."""

    serial: str
    calibration: wire.Calibration
    max_ratings: tuple[float, float, float, float, float, float]

    def __post_init__(self) -> None:
        for name, v in (("counts per force", self.calibration.counts_per_force),
                        ("counts per torque", self.calibration.counts_per_torque)):
            if v != int(v):
                raise ValueError(f"{self.serial}: {name} {v!r} must be a whole number, as the box stores it")


@dataclass(frozen=True)
class Configuration:
    """A configuration slot: its name and which stored calibration it uses."""

    name: str = "empty"
    calibration: int = 0


class BoxWeb:
    """The pages and settings of one box. rate_hz: the fastest rate the RDT stream can be made at
    (the emulator's twin rate); runrate reports ft_sample_rate_hz, the box's internal clock.
    status() and counts() give the status word and the latest (biased) counts for the run* fields.
    """

    def __init__(self, product: str, calibrations: list[StoredCalibration], rate_hz: float,
                 ft_sample_rate_hz: float, buffer_records: int, status=lambda: 0, counts=lambda: (0,) * 6) -> None:
        if not calibrations:
            raise ValueError("a Net F/T box holds at least one calibration")
        if not 1 <= buffer_records <= MAX_BUFFER_RECORDS:
            raise ValueError(f"records per packet {buffer_records} must be 1..{MAX_BUFFER_RECORDS} (comrdtbsiz)")
        self.product = product
        self.calibrations = list(calibrations)
        self.rate_hz = float(rate_hz)
        self.ft_sample_rate_hz = float(ft_sample_rate_hz)
        self._status, self._counts = status, counts
        self.lock = threading.Lock()
        # slot k < len(calibrations) uses calibration k; the others the first (as shipped: "empty")
        self.configurations = [Configuration("empty", k if k < len(calibrations) else 0)
                               for k in range(CONFIGURATION_SLOTS)]
        self.active = 0  # setcfgsel
        self.decimation = 1  # RDT records are every decimation-th twin sample
        self.buffer_records = int(buffer_records)  # comrdtbsiz
        self.ignored: list[tuple[str, str, str]] = []

    # ---- state the emulator reads ------------------------------------------------------------
    @property
    def calibration(self) -> wire.Calibration:
        """The active configuration's calibration: what the RDT counts are scaled by."""
        return self.calibrations[self.configurations[self.active].calibration].calibration

    @property
    def rdt_rate_hz(self) -> int:
        return int(self.rate_hz / self.decimation)

    # ---- HTTP ------------------------------------------------------------------------------------
    def get(self, target: str) -> tuple[int, str, str]:
        """A GET of target (path and query) -> (HTTP status, content type, body)."""
        url = urllib.parse.urlsplit(target)
        query = urllib.parse.parse_qsl(url.query, keep_blank_values=True)
        page = url.path
        with self.lock:
            if page in ("/", "/index.htm", "/index.html"):
                return 200, "text/html", self._start_page()
            if page in ("/netftapi2.xml", "/netftcalapi.xml"):
                index = dict(query).get("index")
                if index is not None and not index.isdigit():
                    return 404, "text/html", ""
                body = self._api(index) if page == "/netftapi2.xml" else self._cal(index)
                return (200, "text/xml", body) if body is not None else (404, "text/html", "")
            if page in ("/setting.cgi", "/comm.cgi", "/config.cgi"):
                self._cgi(page[1:], query)
                return 200, "text/html", f"<html><body>{page[1:]}: done</body></html>\n"
        return 404, "text/html", ""

    def _start_page(self) -> str:
        name = html.escape(self.product)
        return (f"<html><head><title>{name}</title></head><body><h1>{name}</h1>\n"
                "<p><a href=\"netftapi2.xml\">netftapi2.xml</a> <a href=\"netftcalapi.xml\">netftcalapi.xml</a></p>\n"
                "</body></html>\n")

    def _api(self, index: str | None) -> str | None:
        slot = self.active if index is None else int(index)
        if slot >= CONFIGURATION_SLOTS:
            return None
        cfg = self.configurations[slot]
        stored = self.calibrations[cfg.calibration]
        cal = stored.calibration
        fields = {
            "prodname": self.product,
            "runstat": f"0x{self._status() & 0xFFFFFFFF:08X}",
            "runrate": f"{self.ft_sample_rate_hz:.0f}",
            "runft": _list(self._counts()),
            "cfgnam": cfg.name,
            "cfgcalsel": cfg.calibration,
            "cfgcalsn": stored.serial,
            "scfgfu": cal.force_unit,
            "scfgtu": cal.torque_unit,
            "cfgcpf": int(cal.counts_per_force),
            "cfgcpt": int(cal.counts_per_torque),
            "cfgmr": _list(stored.max_ratings),
            "cfgtfx": "0;0;0;0;0;0",
            "scfgtdu": "mm",
            "scfgtau": "degrees",
            "setcfgsel": self.active,
            "comrdte": "Enabled",
            "comrdtrate": self.rdt_rate_hz,
            "comrdtbsiz": self.buffer_records,
        }
        return _document("netft", fields)

    def _cal(self, index: str | None) -> str | None:
        k = self.configurations[self.active].calibration if index is None else int(index)
        if k >= len(self.calibrations):
            return None
        stored = self.calibrations[k]
        cal = stored.calibration
        return _document("netftCalibration", {
            "calsn": stored.serial, "calcpf": int(cal.counts_per_force), "calcpt": int(cal.counts_per_torque),
            "scalfu": cal.force_unit, "scaltu": cal.torque_unit, "calmr": _list(stored.max_ratings)})

    # ---- CGI -------------------------------------------------------------------------------------
    def _cgi(self, page: str, query: list[tuple[str, str]]) -> None:
        values = dict(query)
        if page == "config.cgi" and "cfgid" in values:  # the slot the other config.cgi variables write
            slot = _whole(values.pop("cfgid"), 0, CONFIGURATION_SLOTS - 1)
            if slot is None:
                self._ignore(page, "cfgid", "(slot out of range)")
                return
            for var, raw in values.items():
                cfg = self.configurations[slot]
                if var == "cfgnam":
                    self.configurations[slot] = replace(cfg, name=raw)
                elif var == "cfgcalsel" and (k := _whole(raw, 0, len(self.calibrations) - 1)) is not None:
                    self.configurations[slot] = replace(cfg, calibration=k)
                else:
                    self._ignore(page, var, raw)
            return
        for var, raw in values.items():
            if page == "setting.cgi" and var == "setcfgsel" and (v := _whole(raw, 0, CONFIGURATION_SLOTS - 1)) is not None:
                self.active = v
            elif page == "comm.cgi" and var == "comrdtrate" and (v := _whole(raw, 1, MAX_RDT_RATE_HZ)) is not None:
                # rounded up to a rate the stream can make: the twin's rate over a whole number
                self.decimation = max(1, int(self.rate_hz // v))
            elif page == "comm.cgi" and var == "comrdtbsiz" and (v := _whole(raw, 1, MAX_BUFFER_RECORDS)) is not None:
                self.buffer_records = v
            else:
                self._ignore(page, var, raw)

    def _ignore(self, page: str, var: str, raw: str) -> None:
        self.ignored.append((page, var, raw))
        log.info("netft emulator: %s?%s=%s not applied (not modelled, not this page's, or out of range)",
                 page, var, raw)


def _whole(raw: str, lo: int, hi: int) -> int | None:
    try:
        v = int(raw)
    except ValueError:
        return None
    return v if lo <= v <= hi else None


def _list(values) -> str:
    return ";".join(f"{v:g}" if isinstance(v, float) else str(int(v)) for v in values)


def _document(root: str, fields: dict) -> str:
    body = "".join(f"<{k}>{html.escape(str(v))}</{k}>" for k, v in fields.items())
    return f"<?xml version=\"1.0\"?><{root}>{body}</{root}>\n"
