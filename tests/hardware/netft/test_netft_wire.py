"""RDT wire format on literal bytes (layouts from ATI's Net F/T manual), and the calibration XML."""

import numpy as np
import pytest

from hardware.netft import wire

# A start-streaming request and a stop, as a client puts them on the wire.
START_ENDLESS = bytes.fromhex("1234 0002 00000000")
START_TEN_BUFFERED = bytes.fromhex("1234 0003 0000000a")
BIAS = bytes.fromhex("1234 0042 00000000")
# One record: rdt_sequence 1, ft_sequence 857652 (0x000d1634), status 0,
# Fx -31126, Fy -137872, Fz 114081, Tx 1934, Ty 3811, Tz -3472 counts.
RECORD = bytes.fromhex("00000001 000d1634 00000000 ffff866a fffde570 0001bda1 0000078e 00000ee3 fffff270")
# The box's calibration page (an excerpt; the real one has many more settings).
XML = """<?xml version="1.0" encoding="utf-8"?>
<netft><setserial>FT12345</setserial><prodname>Net F/T</prodname>
<cfgcpf>1000000</cfgcpf><cfgcpt>1000</cfgcpt><scfgfu>N</scfgfu><scfgtu>Nmm</scfgtu><comrdte>1</comrdte></netft>"""


def test_requests_are_eight_big_endian_bytes():
    assert wire.encode_request(wire.CMD_START_REALTIME) == START_ENDLESS
    assert wire.encode_request(wire.CMD_START_BUFFERED, 10) == START_TEN_BUFFERED
    assert wire.encode_request(wire.CMD_BIAS) == BIAS
    assert wire.decode_request(START_TEN_BUFFERED) == (wire.CMD_START_BUFFERED, 10)


def test_bad_requests_are_rejected():
    with pytest.raises(wire.RDTError, match="header"):
        wire.decode_request(bytes.fromhex("4321 0002 00000000"))
    with pytest.raises(wire.RDTError, match="8 bytes"):
        wire.decode_request(START_ENDLESS[:7])


def test_a_record_decodes_to_signed_counts():
    (rec,) = wire.decode_records(RECORD)
    assert (rec.rdt_sequence, rec.ft_sequence, rec.status) == (1, 857652, 0)
    assert rec.counts == (-31126, -137872, 114081, 1934, 3811, -3472)
    assert wire.encode_record(1, 857652, 0, rec.counts) == RECORD


def test_buffered_datagrams_hold_several_records_and_partial_ones_are_rejected():
    second = wire.encode_record(2, 857659, 0x80020000, (1, 2, 3, 4, 5, 6))
    recs = wire.decode_records(RECORD + second)
    assert [r.rdt_sequence for r in recs] == [1, 2]
    assert recs[1].status == 0x80020000
    for bad in (b"", RECORD[:35], RECORD + b"\x00"):
        with pytest.raises(wire.RDTError):
            wire.decode_records(bad)


def test_sequence_numbers_wrap_at_32_bits():
    rec = wire.decode_records(wire.encode_record(2**32 + 5, -1, 0, (0,) * 6))[0]
    assert (rec.rdt_sequence, rec.ft_sequence) == (5, 2**32 - 1)
    assert wire.seq_delta(3, 2**32 - 2) == 5
    assert wire.seq_delta(2**32 - 2, 3) == -5
    assert wire.seq_delta(7, 7) == 0


def test_status_words_are_named():
    assert wire.decode_status(0) == "healthy"
    assert wire.decode_status(0x80020000) == "error summary, transducer saturation or A/D error"


def test_calibration_from_the_box_xml_converts_counts_to_si():
    cal = wire.parse_calibration_xml(XML)
    assert (cal.counts_per_force, cal.counts_per_torque, cal.force_unit, cal.torque_unit) == (1e6, 1e3, "N", "Nmm")
    force, torque = cal.to_si(wire.decode_records(RECORD)[0].counts)
    assert np.allclose(force, [-0.031126, -0.137872, 0.114081])
    assert np.allclose(torque, [1.934e-3, 3.811e-3, -3.472e-3])  # 1000 counts per N·mm
    assert cal.to_counts(force, torque) == (-31126, -137872, 114081, 1934, 3811, -3472)
    # Our own page parses back to the same calibration.
    assert wire.parse_calibration_xml(wire.calibration_xml(cal)) == cal


def test_imperial_units_convert():
    cal = wire.Calibration(1000.0, 1000.0, "lbf", "lbf-in")
    force, torque = cal.to_si((1000, 0, 0, 1000, 0, 0))
    assert force[0] == pytest.approx(4.4482216) and torque[0] == pytest.approx(0.1129848)


def test_bad_calibration_pages_say_what_is_missing():
    with pytest.raises(wire.RDTError, match="cfgcpt"):
        wire.parse_calibration_xml("<netft><cfgcpf>1000000</cfgcpf></netft>")
    with pytest.raises(wire.RDTError, match="not a number"):
        wire.parse_calibration_xml("<netft><cfgcpf>lots</cfgcpf><cfgcpt>1</cfgcpt></netft>")
    with pytest.raises(wire.RDTError, match="unknown force unit"):
        wire.parse_calibration_xml("<netft><cfgcpf>1</cfgcpf><cfgcpt>1</cfgcpt><scfgfu>stone</scfgfu></netft>")
    with pytest.raises(wire.RDTError, match="> 0"):
        wire.parse_calibration_xml("<netft><cfgcpf>0</cfgcpf><cfgcpt>1</cfgcpt></netft>")
