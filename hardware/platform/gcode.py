"""GRBL 1.1's G-code block parser (gnea/grbl `grbl/gcode.c`, `doc/markdown/jogging.md`), the part
a three-axis stage meets: one cleaned block and the parser's modal state in, what the block does
out, or the `error:N` GRBL answers. No I/O and no machine state: the emulator plans and runs it.

Supported as GRBL 1.1h supports them: G0 G1 G4 G17 G20 G21 G53 G54 G90 G91 G94; M0 M1 M2 M30
(program flow), M3 M4 M5 (spindle), M8 M9 (coolant; M7 is compiled out by default); words F N P S
T X Y Z. GRBL drives spindle and coolant pins whether or not anything is wired to them, so S, T
and the M codes are tracked and reported (`$G`, status `A:`) and drive nothing here. A `$J=` jog
takes only G20/G21, G90/G91, G53, N, F and axis words; it needs F and does not change the modal
state. Other G codes GRBL knows (arcs, G10/G28/G30/G92 offsets, probing, G93) answer error:20,
as an unsupported command does. Work offsets are all zero, so work and machine coordinates agree.

Error checks follow gcode.c's order: word format (1, 2), unsupported command (20), non-integer
command value (23), modal-group conflict (21), repeated word (25), tool number (38), negative
F/N/P/S/T (4), line number (27), jog feed missing (22), G4 without P (28), G1 without feed (22),
unused words (36), prohibited jog words (16).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hardware.platform.wire import GcodeError, parse_words

MAX_TOOL_NUMBER = 255  # gcode.h
MAX_LINE_NUMBER = 10_000_000 - 1  # gcode.h (9,999,999)

_G_GROUP = {0: "motion", 1: "motion", 4: "nonmodal", 53: "nonmodal", 17: "plane", 20: "units", 21: "units",
            54: "wcs", 90: "distance", 91: "distance", 94: "feedmode"}
_M_GROUP = {0: "flow", 1: "flow", 2: "flow", 30: "flow", 3: "spindle", 4: "spindle", 5: "spindle",
            8: "coolant", 9: "coolant"}
_JOG_GROUPS = {"distance", "units", "nonmodal"}  # nonmodal: G53 only
_VALUE_WORDS = "FIJKLNPRSTXYZ"  # words gcode.c reads; any other letter is an unsupported command


@dataclass(frozen=True)
class Modal:
    """The parser's persistent state (gc_state): modal groups and the modal words F, S, T."""

    motion: int = 0  # 0 G0 seek, 1 G1 linear
    absolute: bool = True  # G90 (False: G91)
    unit_mm: float = 1.0  # mm per programmed unit: 1 (G21) or 25.4 (G20)
    feed_mm_min: float = 0.0  # F in mm/min; 0 is undefined, as in GRBL
    spindle: int = 5  # M3 CW, M4 CCW, M5 off
    coolant: int = 9  # M8 flood, M9 off
    spindle_rpm: float = 0.0  # S
    tool: int = 0  # T (tracked only, as in GRBL)

    def report(self) -> str:
        """The `[GC:...]` text of `$G` (report.c report_gcode_modes)."""
        return (f"G{self.motion} G54 G17 G{21 if self.unit_mm == 1.0 else 20} G{90 if self.absolute else 91} G94 "
                f"M{self.spindle} M{self.coolant} T{self.tool} F{self.feed_mm_min:.0f} S{self.spindle_rpm:.0f}")

    def program_end(self) -> Modal:
        """M2/M30: G1 G17 G90 G94 G54 M5 M9 again; units, F, S and T are kept (gcode.c)."""
        return replace(self, motion=1, absolute=True, spindle=5, coolant=9)


@dataclass(frozen=True)
class Block:
    """What one block does, in GRBL's order of execution: dwell, motion, program flow."""

    modal: Modal  # the parser state after the block (unchanged by a jog)
    target_mm: np.ndarray | None  # (3,) machine target of the block's motion; None: no motion
    rapid: bool = False  # G0
    dwell_s: float | None = None  # G4 P
    program_flow: int | None = None  # 0 (M0 pause), 2 or 30 (program end); M1 is ignored, as in GRBL
    feed_mm_min: float = 0.0  # the motion's programmed feed (a jog's own F)


def parse_block(block: str, modal: Modal, position_mm: np.ndarray, jog: bool = False) -> Block:
    """One cleaned block (`wire.clean_line`; for a jog, the text after `$J=`) -> Block.

    position_mm: (3,) the parser's position (machine mm), the base of G91 moves and of axes the
    block leaves out. Raises wire.GcodeError with the code GRBL would answer.
    """
    groups: dict[str, int] = {}
    flow = None
    values: dict[str, float] = {}
    spindle, coolant = modal.spindle, modal.coolant
    for letter, val in parse_words(block):
        int_val = int(val)
        mantissa = round(100 * (val - int_val))
        if letter in "GM":
            table = _G_GROUP if letter == "G" else _M_GROUP
            if int_val not in table:
                raise GcodeError(20, f"{letter}{val:g}")
            if mantissa:
                raise GcodeError(23, f"{letter}{val:g}")
            group = table[int_val]
            if group in groups:
                raise GcodeError(21, block)
            groups[group] = int_val
            if group == "flow":
                flow = None if int_val == 1 else int_val
            elif group == "spindle":
                spindle = int_val
            elif group == "coolant":
                coolant = int_val
        elif letter in _VALUE_WORDS:
            if letter == "T" and val > MAX_TOOL_NUMBER:
                raise GcodeError(38, f"T{val:g}")
            if letter in values:
                raise GcodeError(25, letter)
            if letter in "FNPST" and val < 0:
                raise GcodeError(4, f"{letter}{val:g}")
            values[letter] = val
        else:
            raise GcodeError(20, f"{letter}{val:g}")
    if values.get("N", 0) > MAX_LINE_NUMBER:
        raise GcodeError(27, f"N{values['N']:g}")
    unit = {20: 25.4, 21: 1.0}.get(groups.get("units"), modal.unit_mm)
    absolute = {90: True, 91: False}.get(groups.get("distance"), modal.absolute)
    motion = 1 if jog else groups.get("motion", modal.motion)
    if jog:
        if "F" not in values:
            raise GcodeError(22, "a jog needs F")
        feed = values["F"] * unit
    else:
        feed = values["F"] * unit if "F" in values else modal.feed_mm_min
    nonmodal = groups.get("nonmodal")
    dwell = None
    if nonmodal == 4:
        if "P" not in values:
            raise GcodeError(28, "G4 needs P")
        dwell = values.pop("P")
    axes = [a for a in "XYZ" if a in values]
    target = None
    if motion == 1 and not feed and (axes or "motion" in groups):
        raise GcodeError(22, block)
    if axes:
        target = np.array(position_mm, float)
        for i, a in enumerate("XYZ"):
            if a in values:
                v = values[a] * unit
                target[i] = v if (nonmodal == 53 or absolute) else target[i] + v
    used = set("NFXYZ") if jog else set("NFSTXYZ")
    unused = [w for w in values if w not in used]
    if unused:
        raise GcodeError(36, "".join(unused))
    if jog:
        if set(groups) - _JOG_GROUPS or nonmodal not in (None, 53) or target is None:
            # (GRBL 1.1h plans an axis-less jog to machine zero; the docs require an axis word.)
            raise GcodeError(16, block)
        return Block(modal, target, feed_mm_min=feed)
    new = replace(modal, motion=motion, absolute=absolute, unit_mm=unit, feed_mm_min=feed, spindle=spindle,
                  coolant=coolant, spindle_rpm=values.get("S", modal.spindle_rpm),
                  tool=int(values.get("T", modal.tool)))
    return Block(new, target, rapid=motion == 0, dwell_s=dwell, program_flow=flow, feed_mm_min=feed)
