"""Where the writer runs: a child process fed through a pipe (default) or a thread of this process.

Both backends take messages from :class:`~dlo_ros.recording.recorder.Recorder` with ``submit``
(never blocking the caller: when the bounded backlog is full the oldest droppable message goes and
is counted) and answer ``flush`` / ``close`` with the writer's error stats.
"""

from __future__ import annotations

import collections
import logging
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO, Any, cast

from .writer import RecordingUnavailable, WriterConfig, Writer

log = logging.getLogger(__name__)


def _drop_oldest(queue: collections.deque, limit: int) -> int:
    """Drop the oldest droppable entry of ``queue``; return 1 if one was dropped.

    Make room in ``queue`` of (payload, keep) by dropping its oldest droppable entry; returns 1
    if one was dropped.
    """
    if len(queue) < limit:
        return 0
    for i, (_, keep) in enumerate(queue):
        if not keep:
            del queue[i]
            return 1
    return 0


class ThreadBackend:
    """The writer in a background thread of this process (``backend="thread"``).

    The writer in a background thread of this process (``backend="thread"``).  Simple, but
    rerun's Python work shares the GIL with the caller: on a loaded machine it slows the solver
    thread.
    """

    def __init__(self, cfg: WriterConfig, timeout: float, queue_size: int) -> None:
        del timeout
        self.writer = Writer(cfg)
        self.recording_id = self.writer.recording_id
        self.dropped = 0
        self._limit = queue_size
        self._queue: collections.deque = collections.deque()
        self._cond = threading.Condition()
        self._busy = self._stop = False
        self._thread = threading.Thread(target=self._run, name="dlo-recorder", daemon=True)
        self._thread.start()

    @property
    def pending(self) -> int:
        with self._cond:
            return len(self._queue) + int(self._busy)

    def submit(self, message: Any, keep: bool) -> None:
        with self._cond:
            if self._stop:
                return
            self.dropped += _drop_oldest(self._queue, self._limit)
            self._queue.append(((message, self.dropped), keep))
            self._cond.notify_all()

    def _run(self) -> None:
        while True:
            with self._cond:
                while not (self._queue or self._stop):
                    due = self.writer.due()
                    if due == 0.0:
                        break
                    self._cond.wait(due)
                if not self._queue and not self._stop:
                    entry = None  # only a batch to send
                elif not self._queue:
                    return
                else:
                    entry = self._queue.popleft()[0]
                self._busy = True
            try:
                if entry is None:
                    self.writer.send_batches()
                else:
                    self.writer.handle(*entry)
            finally:
                with self._cond:
                    self._busy = False
                    self._cond.notify_all()

    def _drain(self, deadline: float) -> bool:
        with self._cond:
            while self._queue or self._busy:
                if (
                    not self._cond.wait(max(0.0, deadline - time.monotonic()))
                    and time.monotonic() >= deadline
                ):
                    return False
        return True

    def flush(self, timeout: float) -> tuple[bool, dict]:
        deadline = time.monotonic() + timeout
        done = self._drain(deadline)
        self.writer.flush(max(0.1, deadline - time.monotonic()))
        return done, self.writer.stats()

    def close(self, timeout: float) -> dict:
        deadline = time.monotonic() + timeout
        self._drain(deadline)
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._thread.join(max(0.1, deadline - time.monotonic()))
        self.writer.close(max(1.0, deadline - time.monotonic()))
        return self.writer.stats()


def _frame(message: Any) -> bytes:
    data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
    return struct.pack("<I", len(data)) + data


def _write_all(fd: int, data: bytes, deadline: float | None = None) -> None:
    """Write all of ``data`` to a (possibly non-blocking) fd.

    Write all of ``data`` to a (possibly non-blocking) fd, waiting for room until
    ``deadline``.
    """
    view = memoryview(data)
    while view:
        try:
            view = view[os.write(fd, view) :]
        except BlockingIOError:
            wait = None if deadline is None else deadline - time.monotonic()
            if wait is not None and wait <= 0:
                raise TimeoutError("the recorder process does not keep up") from None
            select.select([], [fd], [], wait)


def _read_exact(fd: int, n: int, deadline: float | None) -> bytes | None:
    chunks, left = [], n
    while left:
        if deadline is not None:
            wait = deadline - time.monotonic()
            if wait <= 0 or not select.select([fd], [], [], wait)[0]:
                raise TimeoutError("no answer from the recorder process")
        data = os.read(fd, left)
        if not data:
            return None
        chunks.append(data)
        left -= len(data)
    return b"".join(chunks)


def _read_frame(fd: int, deadline: float | None = None) -> Any:
    header = _read_exact(fd, 4, deadline)
    if header is None:
        return None
    body = _read_exact(fd, struct.unpack("<I", header)[0], deadline)
    return None if body is None else pickle.loads(body)  # noqa: S301 - frames from our own process


F_SETPIPE_SZ = 1031  # Linux fcntl: set a pipe's buffer size
CHILD_NICE = (
    19  # the recorder process runs at the lowest priority: it yields the CPU to the solver
)
CHILD_POLL_SECONDS = (
    0.02  # the recorder process reads its pipe at most this often while data flows
)


class ProcessBackend:
    """The writer in a child process (``backend="process"``, the default).

    ``submit`` pickles the snapshot and writes it into a non-blocking pipe (enlarged to 1 MiB where
    Linux allows): tens of microseconds in the caller's thread, no background Python thread
    competing for the GIL.  Only when the pipe is full does a frame wait in the bounded backlog
    (drop-oldest), which a small thread writes out as soon as the child has read.  The child
    (``python -c 'from dlo_ros.recording.transport import child_main; ...'``) makes every rerun
    call; it ignores SIGINT (Ctrl-C stops the parent, which then closes it) and finishes the
    recording on EOF.
    """

    def __init__(self, cfg: WriterConfig, timeout: float, queue_size: int) -> None:
        env = dict(os.environ)
        package_root = str(Path(__file__).resolve().parents[2])
        env["PYTHONPATH"] = os.pathsep.join(
            [package_root] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])
        )
        code = (
            "import sys; from dlo_ros.recording.transport import child_main; "
            "sys.exit(child_main())"
        )
        self.proc = subprocess.Popen(
            [sys.executable, "-c", code],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=env,
            close_fds=True,
        )
        # stdin and stdout are pipes (PIPE above), never None
        stdin, stdout = cast(IO[bytes], self.proc.stdin), cast(IO[bytes], self.proc.stdout)
        self._in, self._out = stdin.fileno(), stdout.fileno()
        self.dead = False
        self.dropped = 0
        self.stats: dict[str, Any] = {"errors": 0, "last_error": ""}
        try:
            _write_all(self._in, _frame(cfg))
            reply = _read_frame(self._out, time.monotonic() + timeout)
        except (OSError, TimeoutError) as exc:
            self._kill()
            raise RuntimeError(f"the recorder process did not start: {exc}") from None
        if not reply or reply[0] != "ready":
            self._kill()
            message = reply[1] if reply else f"it exited with code {self.proc.poll()}"
            if reply and reply[0] == "unavailable":
                raise RecordingUnavailable(message)
            raise RuntimeError(f"recording could not start: {message}")
        self.recording_id = reply[1]
        try:
            import fcntl  # optional: POSIX only

            fcntl.fcntl(self._in, F_SETPIPE_SZ, 1 << 20)
        except (ImportError, OSError):
            pass
        os.set_blocking(self._in, False)
        self._limit = queue_size
        self._cond = threading.Condition()
        self._backlog: collections.deque = collections.deque()  # (frame bytes, keep)
        self._partial = (
            b""  # the unwritten tail of a frame (never dropped: the stream must stay framed)
        )
        self._stop = False
        self._request_lock = threading.Lock()
        self._thread = threading.Thread(
            target=self._drain_loop, name="dlo-recorder-pipe", daemon=True
        )
        self._thread.start()

    @property
    def pending(self) -> int:
        with self._cond:
            return len(self._backlog) + int(bool(self._partial))

    def submit(self, message: Any, keep: bool) -> None:
        frame = _frame(("item", message, self.dropped))
        with self._cond:
            if self.dead or self._stop:
                return
            if not self._backlog and not self._partial:
                try:
                    n = os.write(self._in, frame)
                except BlockingIOError:
                    n = 0
                except OSError as exc:
                    self._died(exc)
                    return
                if n == len(frame):
                    return
                self._partial = frame[n:]
            else:
                self.dropped += _drop_oldest(self._backlog, self._limit)
                self._backlog.append((frame, keep))
            self._cond.notify_all()

    def _write_some(self) -> bool:
        """Write what is waiting until the pipe is full (lock held); True when nothing is left."""
        while True:
            if not self._partial:
                if not self._backlog:
                    return True
                self._partial = self._backlog.popleft()[0]
            try:
                n = os.write(self._in, self._partial)
            except BlockingIOError:
                return False
            self._partial = self._partial[n:]

    def _drain_loop(self) -> None:
        while True:
            with self._cond:
                while not (self._partial or self._backlog or self._stop):
                    self._cond.wait()
                if self._stop or self.dead:
                    return
            select.select([], [self._in], [], 0.5)  # wait for room, GIL released
            with self._cond:
                if self.dead:
                    return
                try:
                    if self._write_some():
                        self._cond.notify_all()
                except OSError as exc:
                    self._died(exc)
                    return

    def _died(self, exc: BaseException) -> None:
        """Record that the child is gone (lock held): count it once, drop what waits."""
        if not self.dead:
            self.dead = True
            self.stats = {
                "errors": self.stats["errors"] + 1,
                "last_error": f"recorder process: {exc}",
            }
            log.warning("recorder: the recorder process has gone (%s); recording stopped", exc)
        self.dropped += len(self._backlog)
        self._backlog.clear()
        self._partial = b""
        self._cond.notify_all()

    def _request(self, kind: str, timeout: float) -> tuple[bool, dict]:
        """Write everything, then ask the child to ``flush`` or ``close`` and wait.

        Write everything, then ask the child to ``flush`` or ``close`` and wait for its
        answer.
        """
        deadline = time.monotonic() + timeout
        with self._request_lock:
            with self._cond:
                if self.dead:
                    return False, self.stats
                try:
                    while not self._write_some():
                        if time.monotonic() >= deadline:
                            return False, self.stats
                        select.select([], [self._in], [], max(0.0, deadline - time.monotonic()))
                    _write_all(
                        self._in, _frame((kind, max(0.1, deadline - time.monotonic()))), deadline
                    )
                except TimeoutError:
                    return False, self.stats
                except OSError as exc:
                    self._died(exc)
                    return False, self.stats
            try:
                reply = _read_frame(self._out, deadline + 5.0)
            except (OSError, TimeoutError) as exc:
                with self._cond:
                    self._died(exc)
                return False, self.stats
            if reply is None:
                with self._cond:
                    self._died(EOFError("it exited"))
                return False, self.stats
            self.stats = reply[1]
            return True, self.stats

    def flush(self, timeout: float) -> tuple[bool, dict]:
        return self._request("flush", timeout)

    def close(self, timeout: float) -> dict:
        _, stats = self._request("close", timeout)
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._thread.join(1.0)
        for f in (self.proc.stdin, self.proc.stdout):
            try:
                cast(IO[bytes], f).close()
            except OSError:
                pass
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self._kill()
        return stats

    def _kill(self) -> None:
        self.dead = True
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


def child_main() -> int:
    """Entry point of the recorder process: read frames from stdin, log them, answer on stdout."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    inp = sys.stdin.buffer.fileno()
    out = os.dup(1)
    os.dup2(2, 1)  # anything printed in here goes to stderr, never into the answer pipe
    cfg = _read_frame(inp)
    if cfg is None:
        return 0
    try:
        writer = Writer(cfg)
    except RecordingUnavailable as exc:
        _write_all(out, _frame(("unavailable", str(exc))))
        return 1
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises
        _write_all(out, _frame(("error", f"{type(exc).__name__}: {exc}")))
        return 1
    _write_all(out, _frame(("ready", writer.recording_id)))
    if hasattr(os, "nice"):
        try:
            os.nice(CHILD_NICE)  # background work: yield the CPU to the solver on a busy machine
        except OSError:
            pass
    os.set_blocking(inp, False)
    buf = bytearray()
    while True:
        due = writer.due()
        if not select.select([inp], [], [], due)[0]:
            writer.send_batches()
            continue
        eof = False
        while True:  # take everything the pipe holds
            try:
                chunk = os.read(inp, 1 << 20)
            except BlockingIOError:
                break
            if not chunk:
                eof = True
                break
            buf += chunk
        while len(buf) >= 4:
            n = struct.unpack_from("<I", buf)[0]
            if len(buf) < 4 + n:
                break
            message = pickle.loads(bytes(buf[4 : 4 + n]))  # noqa: S301 - frames from our parent
            del buf[: 4 + n]
            if message[0] == "item":
                writer.handle(message[1], message[2])
            elif message[0] == "flush":
                writer.flush(message[1])
                _write_all(out, _frame(("flushed", writer.stats())))
            elif message[0] == "close":
                writer.close(message[1])
                _write_all(out, _frame(("closed", writer.stats())))
                return 0
        if eof:  # the parent went away: finish what was logged
            writer.close()
            return 0
        if writer.due() == 0.0:
            writer.send_batches()
        # Sleep while frames accumulate: a write into the pipe of a reader that is not waiting on
        # it wakes nobody, so a stream of updates costs the solver's process no context switches.
        time.sleep(CHILD_POLL_SECONDS)
