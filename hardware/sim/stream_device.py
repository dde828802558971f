"""What every simulated streaming device shares: its world stream, connect/disconnect, health."""

from __future__ import annotations

from layerskin_exp.sim.streams import Stream
from layerskin_exp.sim.world import World


class SimStreamMixin:
    """A device twin backed by one world stream. The stream acquires only while connected."""

    world: World
    stream: Stream

    def _connect(self) -> None:
        self.stream.clear()
        self.stream.enabled = True
        self._last_seq = None

    def _disconnect(self) -> None:
        self.stream.enabled = False
        self.stream.clear()

    def _drain(self) -> list:
        """Everything the host has received since the last call, oldest first; counts health."""
        self._require_connected()
        out = self.stream.pop_received(self.world.host_now_ns())
        if out:
            self._last_seq = self.health.observe_seqs(self._last_seq, [rec.seq for rec in out])
        return out
