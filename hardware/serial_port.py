"""Opening a serial device as lab software does, and counting what the OS holds for it.

`open_port` takes what a lab's config names: a device path (/dev/ttyACM0, /dev/ttyUSB0, a pty) or
a pyserial URL such as socket://HOST:PORT (a serial device server, a networked controller; the
loopback bench serves its serial emulators this way, see hardware.emulation.TcpSerialLink).
"""

from __future__ import annotations

import fcntl
import socket
import struct
import termios

import serial


def open_port(port: str, baudrate: int, **kwargs) -> serial.SerialBase:
    """pyserial's serial_for_url(port, baudrate, **kwargs); on a socket:// link, bytes are sent
    at once (TCP_NODELAY), not held back to fill a segment, as on a serial line."""
    ser = serial.serial_for_url(port, baudrate, **kwargs)
    if port.startswith("socket://"):
        with socket.fromfd(ser.fileno(), socket.AF_INET, socket.SOCK_STREAM) as sock:  # a duplicate
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return ser


def bytes_waiting(ser) -> int:
    """Bytes the OS holds for the port, on a tty and on a socket:// link alike (FIONREAD;
    pyserial's socket in_waiting says only 0 or 1)."""
    return struct.unpack("I", fcntl.ioctl(ser.fileno(), termios.FIONREAD, b"\0\0\0\0"))[0]
