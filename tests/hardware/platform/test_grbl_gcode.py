"""GRBL 1.1's block parser: the error codes and modal effects gnea/grbl's gcode.c gives the blocks a
lab's G-code sender and jog panel send (expected values read from gcode.c and jogging.md)."""

import numpy as np
import pytest

from hardware.platform.gcode import Modal, parse_block
from hardware.platform.wire import GcodeError

HOME = np.array([0.0, 0.0, 5.0])


def error(block, jog=False):
    with pytest.raises(GcodeError) as exc:
        parse_block(block, Modal(), HOME, jog)
    return exc.value.code


@pytest.mark.parametrize("block", ["M0", "M1", "M2", "M30", "M5", "M9", "S0", "T0", "M3S1000", "M4", "M8",
                                   "G53", "G53G0X1", "N10G1X1F100", "G91G1X1F100M5M9S0T0"])
def test_blocks_a_job_header_or_footer_carries_are_accepted(block):
    parse_block(block, Modal(), HOME)


@pytest.mark.parametrize("block,code", [
    ("M7", 20),  # mist coolant is compiled out by default (config.h ENABLE_M7)
    ("M6", 20), ("A1", 20),
    ("G2X1Y1I1", 20), ("G92X0", 20),  # arcs and offsets: GRBL has them, this stage's emulator does not
    ("M1.5", 23), ("G1.5X1", 23),
    ("M3M5", 21), ("M2M30", 21), ("G4G53P1", 21), ("G0G1X1", 21),
    ("X1X2", 25), ("T256", 38), ("S-1", 4), ("F-1", 4), ("N10000000", 27),
    ("G4", 28), ("G1X1", 22), ("G1", 22),
    ("G0X1P1", 36), ("G0X1I1", 36), ("G1X1F100R2", 36),
])
def test_errors_as_gcode_c_answers_them(block, code):
    assert error(block) == code


def test_modal_words_and_program_end():
    blk = parse_block("G20G91G1X1F10M3S800M8T3", Modal(), HOME)
    m = blk.modal
    assert (m.motion, m.absolute, m.unit_mm, m.feed_mm_min, m.spindle, m.coolant, m.spindle_rpm, m.tool) == \
        (1, False, 25.4, 254.0, 3, 8, 800.0, 3)
    assert np.allclose(blk.target_mm, [25.4, 0.0, 5.0]) and not blk.rapid
    assert m.report() == "G1 G54 G17 G20 G91 G94 M3 M8 T3 F254 S800"
    end = parse_block("M30", m, HOME)
    assert end.program_flow == 30 and end.target_mm is None
    # M2/M30 reset motion, plane, distance, feed mode, WCS, spindle and coolant; units, F, S, T stay
    assert end.modal.program_end().report() == "G1 G54 G17 G20 G90 G94 M5 M9 T3 F254 S800"
    assert parse_block("M1", Modal(), HOME).program_flow is None  # optional stop: ignored
    assert parse_block("M0", Modal(), HOME).program_flow == 0


def test_g53_moves_in_machine_coordinates_whatever_the_distance_mode():
    incremental = Modal(absolute=False)
    assert np.allclose(parse_block("G0X1", incremental, HOME).target_mm, [1.0, 0.0, 5.0])
    blk = parse_block("G53G0X1Z2", incremental, np.array([3.0, 4.0, 5.0]))
    assert np.allclose(blk.target_mm, [1.0, 4.0, 2.0]) and blk.rapid
    assert blk.modal.absolute is False  # G53 is non-modal


def test_dwell_runs_before_the_motion_of_its_block():
    blk = parse_block("G4P0.5G1X1F100", Modal(), HOME)
    assert blk.dwell_s == 0.5 and np.allclose(blk.target_mm, [1.0, 0.0, 5.0])


def test_jog_uses_its_own_modes_and_feed_and_leaves_the_parser_state_alone():
    modal = Modal(motion=0, absolute=True, feed_mm_min=50.0)
    blk = parse_block("G91G20X1F10", modal, HOME, jog=True)
    assert np.allclose(blk.target_mm, [25.4, 0.0, 5.0]) and blk.feed_mm_min == 254.0
    assert blk.modal == modal and blk.program_flow is None and not blk.rapid
    assert np.allclose(parse_block("G53Z2F100", Modal(absolute=False), HOME, jog=True).target_mm, [0.0, 0.0, 2.0])


@pytest.mark.parametrize("block,code", [
    ("X1", 22),  # F is required in every jog, never modal
    ("G1X1F100", 16), ("G0X1F100", 16), ("G4P1X1F100", 16), ("M3X1F100", 16), ("G54X1F100", 16),
    ("F100", 16),  # no axis word
    ("X1F100S0", 36), ("X1F100T1", 36),  # S and T are words a jog does not use
])
def test_jog_errors(block, code):
    assert error(block, jog=True) == code
