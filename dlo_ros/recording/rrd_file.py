"""Opening an ``.rrd`` for ``dlo replay`` with bounded cost, and finding where a cut-off one ends.

rerun 0.41 writes an ``.rrd`` as a stream: a 12-byte header (``RRF2``, the writer's version, 4
bytes of encoding options), then messages, each a 16-byte header (kind: u64 little-endian, payload
length: u64) and the payload (protobuf; kind 1 store info, 2 a chunk, 3 a blueprint activation),
then an end message (kind 0, whose payload is the manifest) and a 32-byte footer.  A writer that is
killed leaves the file cut anywhere; rerun's reader then refuses the whole file ("exceeds file
size").  :func:`open_rrd` walks the message headers only (16 bytes read per message, payloads
skipped), and when the file ends inside a message it copies the complete messages into a temporary
file, which rerun reads as a footer-less (legacy) recording.

Every refusal is a :class:`RrdFileError` (a ValueError) with one line naming the file.
"""

from __future__ import annotations

import contextlib
import os
import struct
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from ..scene import FileLimitError, open_regular_file

#: What ``dlo replay`` accepts (msg_docs/recording.md, "Limits").  A 10-minute recording at 100 Hz
#: (default_cable, 51 output points, paced like the node) is ~280 MB and 60,000 updates.
LIMITS = {
    "file_bytes": 1 << 30,  # 1 GiB
    "messages": 1_000_000,  # rrd messages (chunks) in the file
    "entities": 10_000,  # distinct entity paths
    "updates": 250_000,  # rows of data/result (and of each other entity read back)
    "samples": 10_000,  # centreline samples per result (solver.output_points at most)
    "kept_bytes": 768 << 20,  # what is kept from the file, 768 MiB: numbers (8 bytes
    "row_bytes": 1024,  # each), text (1 per character) and 1 KiB per row kept
}

MAGIC = b"RRF2"
HEADER_BYTES = 12
MESSAGE_HEADER = struct.Struct("<QQ")
KIND_END = 0
FOOTER_MAGIC = b"RRF2FOOT"  # then a u32 version: the last 12 bytes of a whole file
FOOTER_BYTES = 32
KINDS = (0, 1, 2, 3)  # end, store info, chunk, blueprint activation (rerun 0.41)


class RrdFileError(ValueError):
    """The file cannot be read as a recording: one line naming the file and what is wrong."""


@dataclass(frozen=True)
class RrdLayout:
    """What the walk over the message headers found."""

    file_bytes: int
    messages: int  # complete messages, the end message excluded
    complete_bytes: int  # header + complete messages (== file_bytes for a whole file)
    truncated: bool  # it ends inside a message, before its end message or inside the footer


def _open_regular(path: Path) -> int:
    """Open ``path``, a regular file within the size limit, and return its descriptor.

    A descriptor on ``path``, a regular file within the size limit (``scene.open_regular_file``:
    opened without blocking and checked with fstat).
    """
    try:
        return open_regular_file(
            path,
            str(path),
            LIMITS["file_bytes"],
            "recording (.rrd)",
            "msg_docs/recording.md, Limits",
        )
    except FileLimitError as exc:
        if not os.path.lexists(path):
            raise FileNotFoundError(f"{path}: no such file") from None
        raise RrdFileError(str(exc)) from None


def _read_at(fd: int, n: int, offset: int) -> bytes:
    return os.pread(fd, n, offset)


def scan(fd: int, path: Path) -> RrdLayout:
    """Walk the messages of the open file ``fd`` and find where the complete ones end.

    Walk the messages of the open file ``fd``: check the header, each message's kind and count,
    and find the end of the last complete message.
    """
    size = os.fstat(fd).st_size
    if size == 0:
        raise RrdFileError(f"{path}: the file is empty, not a rerun recording (.rrd)")
    head = _read_at(fd, HEADER_BYTES, 0)
    if not head.startswith(MAGIC[: len(head)]) or len(head) < len(MAGIC):
        raise RrdFileError(
            f"{path}: not a rerun recording (.rrd): it does not start with {MAGIC.decode()}"
        )
    if len(head) < HEADER_BYTES:
        raise RrdFileError(f"{path}: the file ends inside the rrd header ({size} bytes)")
    compression, serializer, pad1, pad2 = head[8:12]
    if compression not in (0, 1) or serializer != 2 or pad1 or pad2:
        raise RrdFileError(
            f"{path}: unknown rrd encoding options {head[8:12].hex()} (not written by rerun 0.41)"
        )
    offset, count, limit = HEADER_BYTES, 0, LIMITS["messages"]
    while offset < size:
        raw = _read_at(fd, MESSAGE_HEADER.size, offset)
        if len(raw) < MESSAGE_HEADER.size:
            return RrdLayout(size, count, offset, True)
        kind, length = MESSAGE_HEADER.unpack(raw)
        if kind not in KINDS:
            raise RrdFileError(
                f"{path}: garbled rrd message at byte {offset} (kind {kind}, not "
                "one rerun 0.41 writes)"
            )
        end = offset + MESSAGE_HEADER.size + length
        if end > size:
            return RrdLayout(size, count, offset, True)
        if kind == KIND_END:  # the footer follows (rerun reads the file without it, too)
            tail = _read_at(fd, len(FOOTER_MAGIC) + 4, size - len(FOOTER_MAGIC) - 4)
            whole = size - end >= FOOTER_BYTES and tail.startswith(FOOTER_MAGIC)
            return RrdLayout(size, count, size, not whole)
        count += 1
        if count > limit:
            raise RrdFileError(
                f"{path}: more than {limit} rrd messages (msg_docs/recording.md, Limits)"
            )
        offset = end
    # no end message: a writer that was killed between two messages (rerun reads this as legacy)
    return RrdLayout(size, count, offset, True)


def _copy_prefix(fd: int, n: int, path: Path) -> str:
    """Copy the first ``n`` bytes of ``fd`` into a new temporary file (1 MiB at a time)."""
    out = tempfile.NamedTemporaryFile(  # noqa: SIM115 - removed by open_rrd
        prefix="dlo_replay_", suffix=".rrd", delete=False
    )
    try:
        with out:
            done = 0
            while done < n:
                piece = _read_at(fd, min(1 << 20, n - done), done)
                if not piece:
                    raise RrdFileError(f"{path}: the file shrank while it was read")
                out.write(piece)
                done += len(piece)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(out.name)
        raise
    return out.name


@contextlib.contextmanager
def open_rrd(path: str | Path) -> Iterator[tuple[str, RrdLayout]]:
    """``(name rerun can read, layout)`` for the recording at ``path``, checked and bounded.

    Raises FileNotFoundError or :class:`RrdFileError`.  For a whole file the name is the open
    descriptor's ``/proc/self/fd`` entry where there is one (so rerun reads the very file that was
    checked); for a truncated one it is a temporary copy of its complete messages, removed on exit.
    """
    path = Path(path)
    fd = _open_regular(path)
    temp = None
    try:
        layout = scan(fd, path)
        if layout.truncated and layout.complete_bytes < layout.file_bytes:
            temp = _copy_prefix(fd, layout.complete_bytes, path)
            name = temp
        else:
            proc = f"/proc/self/fd/{fd}"
            name = proc if os.path.exists(proc) else str(path)
        yield name, layout
    finally:
        os.close(fd)
        if temp is not None:
            with contextlib.suppress(OSError):
                os.unlink(temp)
