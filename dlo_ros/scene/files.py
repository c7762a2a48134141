"""Reading a file with limits: a regular file, at most so many bytes, checked before it is read.

The scene reader, the node's parameters file, the recordings and the observation files of
``dlo fit`` all open their files here, so a directory, a FIFO, a device or a huge file is refused
the same way, with one line naming the file.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from .format import LIMITS, SceneError


class FileLimitError(ValueError):
    """A file refused by :func:`read_regular_file`: one line starting with its source name."""


def open_regular_file(
    path: Path | str,
    source: str,
    limit: int,
    what: str = "scene file",
    doc: str = "msg_docs/scene_format.md, Limits",
) -> int:
    """Open a regular file of at most ``limit`` bytes read-only and return its descriptor.

    The caller closes it.  Raises FileLimitError naming ``source`` otherwise.  Opened without
    blocking (a FIFO without a writer would hang a plain open) and checked with fstat on the open
    descriptor before a byte is read, so a directory, a FIFO or a device (/dev/zero) is refused by
    kind, and a huge file by size, whatever happens to the path meanwhile.  ``what`` names the
    kind of file in the messages, ``doc`` where its limits are documented.
    """
    a = "an" if what[:1] in "aeiou" else "a"
    try:
        fd = os.open(
            path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
        )
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise FileLimitError(f"{source}: cannot open the {what}: {reason}") from None
    try:
        info = os.fstat(fd)
        if stat.S_ISDIR(info.st_mode):
            raise FileLimitError(f"{source}: is a directory, not {a} {what}")
        if not stat.S_ISREG(info.st_mode):
            raise FileLimitError(
                f"{source}: not a regular file (a FIFO, socket or device); {a} "
                f"{what} must be a regular file"
            )
        if info.st_size > limit:
            raise FileLimitError(
                f"{source}: the file has {info.st_size} bytes, {a} {what} at most {limit} ({doc})"
            )
    except BaseException:
        os.close(fd)
        raise
    return fd


def read_regular_file(
    path: Path | str,
    source: str,
    limit: int,
    what: str = "scene file",
    doc: str = "msg_docs/scene_format.md, Limits",
) -> bytes:
    """Return the bytes of a regular file of at most ``limit`` bytes (:func:`open_regular_file`).

    Raises FileLimitError naming ``source`` otherwise; a file that grew past ``limit`` after the
    check is refused too.
    """
    a = "an" if what[:1] in "aeiou" else "a"
    fd = open_regular_file(path, source, limit, what, doc)
    try:
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 16, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
        if size > limit:  # it grew after fstat
            raise FileLimitError(
                f"{source}: the file has more than {limit} bytes, {a} {what} at "
                f"most {limit} ({doc})"
            )
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise FileLimitError(f"{source}: cannot read the {what}: {reason}") from None
    finally:
        os.close(fd)
    return b"".join(chunks)


def read_scene_text(path: Path | str, source: str) -> str:
    """Return the text of a scene (or parameters) file, or raise SceneError naming ``source``.

    The file must be a regular file of at most LIMITS['file_bytes'] bytes
    (:func:`read_regular_file`), in UTF-8.
    """
    try:
        data = read_regular_file(path, source, LIMITS["file_bytes"])
    except FileLimitError as exc:
        message = str(exc).replace(
            "a scene file must be a regular file", "a scene must be a YAML file"
        )
        raise SceneError(message, source=source) from None
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SceneError(
            f"{source}: not a UTF-8 text file ({exc.reason} at byte {exc.start})", source=source
        ) from None
