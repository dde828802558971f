"""The Net F/T box's web pages and CGI settings (hardware/netft/web.py), read the way ATI's Net F/T
demo and lab scripts read them; no sockets."""

import xml.etree.ElementTree as ET

import pytest

from hardware.netft import web, wire

HALF_RANGE = web.StoredCalibration("FT00002", wire.Calibration(2_000_000.0, 4_000_000.0, "N", "N-m"),
                                   (10.0, 10.0, 30.0, 0.5, 0.5, 0.5))


@pytest.fixture
def box():
    full = web.StoredCalibration("FT00001", wire.Calibration(1_000_000.0, 1_000_000.0, "N", "N-m"),
                                 (20.0, 20.0, 60.0, 1.0, 1.0, 1.0))
    return web.BoxWeb("Net F/T (test)", [full, HALF_RANGE], rate_hz=1000.0, ft_sample_rate_hz=7000.0,
                      buffer_records=10, status=lambda: 0x80020000, counts=lambda: (1, -2, 3, -4, 5, -6))


def fields(box, target):
    code, ctype, body = box.get(target)
    assert (code, ctype) == (200, "text/xml"), (target, code)
    return {e.tag: e.text for e in ET.fromstring(body)}


def test_netftapi2_has_the_fields_clients_read_with_integer_counts(box):
    f = fields(box, "/netftapi2.xml")
    assert int(f["cfgcpf"]) == 1_000_000 and int(f["cfgcpt"]) == 1_000_000  # int(), not float(): whole numbers
    assert (f["setcfgsel"], f["cfgcalsel"], f["cfgcalsn"], f["prodname"]) == ("0", "0", "FT00001", "Net F/T (test)")
    assert (f["scfgfu"], f["scfgtu"], f["comrdtrate"], f["comrdtbsiz"], f["runrate"]) == ("N", "N-m", "1000", "10", "7000")
    assert f["cfgmr"].split(";") == ["20", "20", "60", "1", "1", "1"]
    assert f["runstat"] == "0x80020000" and f["runft"] == "1;-2;3;-4;5;-6"


def test_the_atis_demo_sequence_finds_the_active_calibration_serial(box):
    active = int(fields(box, "/netftapi2.xml?index=0")["setcfgsel"])
    cal_index = int(fields(box, f"/netftapi2.xml?index={active}")["cfgcalsel"])
    cal = fields(box, f"/netftcalapi.xml?index={cal_index}")
    assert (cal["calsn"], int(cal["calcpf"]), int(cal["calcpt"]), cal["scalfu"], cal["scaltu"]) == \
        ("FT00001", 1_000_000, 1_000_000, "N", "N-m")
    assert fields(box, "/netftcalapi.xml?index=1")["calsn"] == "FT00002"


def test_setcfgsel_switches_the_active_configuration_and_its_calibration(box):
    assert box.get("/setting.cgi?setcfgsel=1")[0] == 200
    f = fields(box, "/netftapi2.xml")
    assert (f["setcfgsel"], f["cfgcalsel"], f["cfgcalsn"], int(f["cfgcpf"]), int(f["cfgcpt"])) == \
        ("1", "1", "FT00002", 2_000_000, 4_000_000)
    assert box.calibration == HALF_RANGE.calibration
    assert fields(box, "/netftcalapi.xml")["calsn"] == "FT00002"  # default: the active configuration's
    assert fields(box, "/netftapi2.xml?index=0")["cfgcalsn"] == "FT00001"  # another slot, shown by index


def test_comrdtrate_is_rounded_up_to_a_rate_the_stream_makes(box):
    for asked, made in (("250", 250), ("300", 333), ("1000", 1000), ("7000", 1000)):
        box.get(f"/comm.cgi?comrdtrate={asked}")
        assert fields(box, "/netftapi2.xml")["comrdtrate"] == str(made) and box.rdt_rate_hz == made
    box.get("/comm.cgi?comrdtbsiz=40")
    assert box.buffer_records == 40


def test_what_the_box_would_not_apply_is_ignored_and_recorded(box):
    box.get("/comm.cgi?comrdtrate=0&comrdtbsiz=41&setcfgsel=1")  # out of range; setcfgsel is setting.cgi's
    box.get("/setting.cgi?setuserfilter=3")  # the filter is not modelled
    assert box.ignored == [("comm.cgi", "comrdtrate", "0"), ("comm.cgi", "comrdtbsiz", "41"),
                           ("comm.cgi", "setcfgsel", "1"), ("setting.cgi", "setuserfilter", "3")]
    f = fields(box, "/netftapi2.xml")
    assert (f["comrdtrate"], f["comrdtbsiz"], f["setcfgsel"]) == ("1000", "10", "0")


def test_config_cgi_names_a_slot_and_picks_its_calibration(box):
    box.get("/config.cgi?cfgid=2&cfgnam=rod%20rig&cfgcalsel=1")
    f = fields(box, "/netftapi2.xml?index=2")
    assert (f["cfgnam"], f["cfgcalsel"], f["cfgcalsn"]) == ("rod rig", "1", "FT00002")


def test_start_page_and_unknown_pages(box):
    code, ctype, body = box.get("/")
    assert code == 200 and ctype == "text/html" and "Net F/T (test)" in body
    for target in ("/nothing.htm", "/netftapi2.xml?index=16", "/netftcalapi.xml?index=2", "/netftapi2.xml?index=x"):
        assert box.get(target)[0] == 404, target


def test_a_calibration_the_box_could_not_store_is_refused():
    with pytest.raises(ValueError, match="whole number"):
        web.StoredCalibration("FT9", wire.Calibration(1234.5, 1000.0), (1.0,) * 6)
