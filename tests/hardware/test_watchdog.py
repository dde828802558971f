"""The watchdogs' bookkeeping (hardware.watchdog), on made-up host times: a polled device's
silence, and a stamped device's clock."""

from __future__ import annotations

from hardware.watchdog import DRIFT_ALLOWANCE, DeviceClock, ReplyWatch

MS = 1_000_000


def test_an_answer_read_while_the_request_was_being_sent_answers_it():
    """GRBL's '?' poller and its reader are two threads: the reader may take the report before the
    poller, descheduled after writing, records the request. That request is answered; if the
    poller then stays late, no unanswered request may be left to count as silence (seen under
    load: a report read 0.5 ms before the poller recorded its '?')."""
    watch = ReplyWatch(allowance_ns=40 * MS)
    watch.answered(0)
    watch.answered(105 * MS)  # the report to the '?' whose sending began at 100 ms
    watch.asked(110 * MS, sending_from_ns=100 * MS)
    assert watch.silent_ns(300 * MS) is None  # the poller late by 190 ms: a busy host, not a silent GRBL


def test_a_request_left_unanswered_is_silence_from_the_last_answer():
    watch = ReplyWatch(allowance_ns=40 * MS)
    watch.answered(105 * MS)
    watch.asked(121 * MS, sending_from_ns=120 * MS)  # no answer since sending began
    assert watch.silent_ns(160 * MS) is None  # waited 39 ms: within the allowance
    assert watch.silent_ns(162 * MS) == 57 * MS  # waited 41 ms: silent since the last answer
    watch.asked(131 * MS, sending_from_ns=130 * MS)  # a later request keeps the oldest's time
    assert watch.silent_ns(162 * MS) == 57 * MS
    watch.answered(170 * MS)
    assert watch.silent_ns(400 * MS) is None


def test_a_request_sent_without_its_start_counts_from_when_it_was_sent():
    """A reply read on the sending thread itself (the Hand-E's) cannot come before the request
    is recorded: such a request is recorded as sent."""
    watch = ReplyWatch(allowance_ns=40 * MS)
    watch.answered(105 * MS)
    watch.asked(110 * MS)
    assert watch.silent_ns(151 * MS) == 46 * MS


def test_device_clock_places_the_newest_sample_by_the_smallest_offset():
    clock = DeviceClock()
    assert clock.silent_ns(0) is None
    clock.observe(device_ns=1_000 * MS, host_ns=5_000 * MS)  # offset 4000 ms
    clock.observe(device_ns=1_010 * MS, host_ns=5_060 * MS)  # received 50 ms late: the offset stays,
    drift = int(10 * MS * DRIFT_ALLOWANCE)  # but for the drift allowed over the 10 ms between them
    assert clock.newest_host_ns == 5_010 * MS + drift
    assert clock.silent_ns(5_070 * MS) == 60 * MS - drift
    clock.observe(device_ns=1_005 * MS, host_ns=5_070 * MS)  # an older sample: nothing new
    assert clock.newest_device_ns == 1_010 * MS
