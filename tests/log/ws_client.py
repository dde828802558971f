"""A minimal WebSocket client (RFC 6455) speaking Foxglove's WebSocket protocol, from the
standard library only: the live-view test's independent reader of what the server sends."""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import threading


class FoxgloveClient:
    def __init__(self, host: str, port: int, subprotocol: str = "foxglove.sdk.v1", timeout: float = 10.0,
                 path: str = "/", headers: dict[str, str] | None = None):
        """headers: extra request headers (Origin, or a Host other than host:port)."""
        self.sock = socket.create_connection((host, port), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        fields = {"Host": f"{host}:{port}", **(headers or {})}
        extra = "".join(f"{k}: {v}\r\n" for k, v in fields.items())
        self.sock.sendall((f"GET {path} HTTP/1.1\r\n{extra}Upgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                           f"Sec-WebSocket-Protocol: {subprotocol}\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(1)
            if not chunk:
                raise ConnectionError("server closed during the handshake")
            head += chunk
        status = head.split(b"\r\n", 1)[0]
        if b" 101 " not in status:
            raise ConnectionError(f"handshake refused: {head.decode(errors='replace')}")
        self.channels: dict[int, dict] = {}  # channel id -> advertisement
        self.server_info: dict | None = None
        self.messages: list[tuple[int, int, bytes]] = []  # (channel id, log time ns, payload)
        self._subs: dict[int, int] = {}  # subscription id -> channel id
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None

    # ---------------------------------------------------------------- frames
    def _recv_exact(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("connection closed")
            buf += chunk
        return buf

    def _recv_frame(self) -> tuple[int, bytes]:
        b0, b1 = self._recv_exact(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", self._recv_exact(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", self._recv_exact(8))[0]
        mask = self._recv_exact(4) if b1 & 0x80 else None
        data = self._recv_exact(n)
        if mask:
            data = bytes(c ^ mask[i % 4] for i, c in enumerate(data))
        return b0 & 0x0F, data  # fragmented messages are not used by the server for these sizes

    def _send(self, opcode: int, data: bytes) -> None:
        mask = os.urandom(4)
        n = len(data)
        head = bytes((0x80 | opcode,))
        if n < 126:
            head += bytes((0x80 | n,))
        elif n < 65536:
            head += bytes((0x80 | 126,)) + struct.pack(">H", n)
        else:
            head += bytes((0x80 | 127,)) + struct.pack(">Q", n)
        self.sock.sendall(head + mask + bytes(c ^ mask[i % 4] for i, c in enumerate(data)))

    # ---------------------------------------------------------------- protocol
    def _handle(self, opcode: int, data: bytes) -> bool:
        if opcode == 0x1:
            msg = json.loads(data)
            if msg["op"] == "serverInfo":
                self.server_info = msg
            elif msg["op"] == "advertise":
                with self._lock:
                    for ch in msg["channels"]:
                        self.channels[ch["id"]] = ch
        elif opcode == 0x2 and data[0] == 0x01:  # messageData
            sub, t = struct.unpack_from("<IQ", data, 1)
            with self._lock:
                self.messages.append((self._subs.get(sub, -1), t, data[13:]))
        elif opcode == 0x9:
            self._send(0xA, data)
        elif opcode == 0x8:
            return False
        return True

    def read_until(self, done, limit: int = 10_000) -> None:
        """Handle frames until done(self) (checked after each) or `limit` frames."""
        for _ in range(limit):
            if done(self):
                return
            if not self._handle(*self._recv_frame()):
                return

    def subscribe(self, channel_ids) -> None:
        subs = []
        with self._lock:
            for cid in channel_ids:
                sid = len(self._subs) + 1
                self._subs[sid] = cid
                subs.append({"id": sid, "channelId": cid})
        self._send(0x1, json.dumps({"op": "subscribe", "subscriptions": subs}).encode())

    def start(self) -> None:
        """Keep reading in a thread (until the connection ends)."""
        # the connect timeout guards the handshake; a busy trial may stay silent for longer
        self.sock.settimeout(None)

        def run():
            try:
                self.read_until(lambda _: False, limit=10**9)
            except (ConnectionError, OSError):
                pass

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()

    def close(self) -> None:
        try:
            self._send(0x8, b"")
        except OSError:
            pass
        self.sock.close()
        if self._thread is not None:
            self._thread.join(timeout=5)
