"""`python -m hardware.emulate DEVICE`: a standalone emulator takes its device's usual ports, so
third-party clients that hard-code them (pyNetFT, a URCap socket client) reach it unchanged."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys

import pytest

from hardware.emulation import free_loopback_host
from tests.protocols.conftest import REPO

UDP, TCP = socket.SOCK_DGRAM, socket.SOCK_STREAM


class Standalone:
    """The launcher in a subprocess; `line` is what it printed once ready."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "hardware.emulate", *args], cwd=REPO,
                                     env={**os.environ, "PYTHONPATH": str(REPO)}, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        self.line = self.proc.stdout.readline()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                assert self.proc.wait(timeout=10) == 0
            finally:
                if self.proc.poll() is None:
                    self.proc.kill()
                    self.proc.wait()
        self.proc.stdout.close()
        self.proc.stderr.close()


def test_netft_takes_the_box_ports_and_serves_its_calibration_to_pynetft():
    pynetft = pytest.importorskip("pynetft")
    host = free_loopback_host({49152: UDP, 80: TCP})
    with Standalone("netft", "--host", host) as emu:
        assert emu.line.startswith(f"netft emulator listening on {host}:49152 (calibration page "
                                   f"http://{host}:80/netftapi2.xml)"), emu.line + emu.proc.stderr.read()
        client = pynetft.Client(pynetft.Config(sensor_host=host))  # the client's defaults: RDT 49152, HTTP 80
        with client:
            it = client.samples(timeout=3.0)
            samples = [next(it) for _ in range(50)]
            health = client.health()
        assert health.sensor_configuration.source == pynetft.CalibrationSource.SENSOR  # read from the box
        assert health.sensor_configuration.calibration.counts_per_force_unit == 1_000_000.0
        assert health.fault_code == pynetft.FaultCode.NONE and len(samples) == 50


def test_hande_takes_the_urcap_port():
    host = free_loopback_host({63352: TCP})
    with Standalone("hande", "--host", host) as emu:
        assert emu.line.startswith(f"hande emulator listening on {host}:63352"), emu.line + emu.proc.stderr.read()
        with socket.create_connection((host, 63352), timeout=5.0) as s:
            s.sendall(b"GET STA\n")
            assert s.recv(64) == b"STA 0\n"


@pytest.mark.parametrize("host, why", [
    ("evil host", "must be an IP address (127.0.0.1, ::1) or a host name"),
    ("a;rm -rf", "must be an IP address (127.0.0.1, ::1) or a host name"),
    ("999.1.1.1", "is not a valid IPv4 address"),
    ("[::1]", "must be an IPv6 address without brackets"),
    ("", "must be an IP address or a host name"),
])
def test_a_bad_host_is_refused_in_one_line_before_anything_starts(capsys, host, why):
    from hardware.emulate import main

    with pytest.raises(SystemExit) as stop:
        main(["netft", "--host", host])
    err = capsys.readouterr().err.strip().splitlines()
    assert stop.value.code == 2 and "Traceback" not in "\n".join(err)
    assert err[-1].startswith(f"python -m hardware.emulate: error: argument --host: {host!r} {why}")


@pytest.mark.parametrize("host", ["127.0.0.1", "::1", "localhost", "lab-pc.local", "10.0.0.7"])
def test_an_address_or_host_name_passes(host):
    from layerskin_exp.config import host_problem

    assert host_problem(host) is None
