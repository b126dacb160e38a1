"""Read TensorBoard event files back in tests (the ``--tb`` writer's output), with tensorboardX's protobuf."""

from __future__ import annotations

import struct


def scalar_events(folder) -> list[tuple]:
    """``(run, tag, step, value)`` of every scalar in the event files under ``folder`` (``run``: the file's
    folder name). TFRecord framing: length u64, its crc u32, the Event proto, its crc u32."""
    from tensorboardX.proto import event_pb2

    out = []
    for path in sorted(folder.rglob("events.out.tfevents.*")):
        data, pos = path.read_bytes(), 0
        while pos < len(data):
            (n,) = struct.unpack("<Q", data[pos:pos + 8])
            event = event_pb2.Event.FromString(data[pos + 12:pos + 12 + n])
            pos += 12 + n + 4
            for v in event.summary.value:
                out.append((path.parent.name, v.tag, event.step, v.simple_value))
    return out
