"""How the writer draws an envelope (``Recorder.log_envelope``): its tube and its summary."""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from .codec import EnvelopeSnap, QueueItem
from .paths import E_ENVELOPE, E_ENVELOPE_EVENTS, TIMELINE_ROS, TIMELINE_UPDATE

#: the tube's colour (RGBA 0-255): translucent orange, as the node's ~/envelope markers
TUBE_RGBA = (255, 140, 26, 64)


class EnvelopeDrawing:
    """The writer's ``_handle_envelope`` (a mixin of ``writer.Writer``, which owns ``rec``)."""

    rec: Any
    _rr: Any

    def send_batches(self) -> None:  # pragma: no cover - the Writer's
        """Send the buffered rows (``writer.Writer.send_batches``)."""
        raise NotImplementedError

    def _handle_envelope(self, item: QueueItem) -> None:
        snap: EnvelopeSnap = item.payload
        self.send_batches()  # keep the rows of earlier updates before this one
        self.rec.set_time(TIMELINE_UPDATE, sequence=int(cast(int, item.update)))
        self.rec.set_time(TIMELINE_ROS, timestamp=np.datetime64(int(item.ros_time_ns), "ns"))
        self.rec.log(
            E_ENVELOPE,
            self._rr.Points3D(snap.points, radii=snap.radii, colors=[TUBE_RGBA]),
        )
        self.rec.log(E_ENVELOPE_EVENTS, self._rr.TextLog(snap.text))
