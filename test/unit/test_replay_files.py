"""`dlo replay` on files it should refuse, on cut-off recordings, and its memory (issue #35).

Every malformed file gives exit code 2 and one line on stderr naming the file, without a
traceback (the CLI runs as a subprocess).  A recording cut at any byte is read up to its last
complete message, and what it holds equals the first updates of the whole recording exactly.
Checking a recording before the viewer starts does not keep its updates: its peak memory does not
grow with them.
"""
from __future__ import annotations

import os
import struct
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun", reason="rerun-sdk needs Python >= 3.11")

from dlo_ros.recording import Recorder  # noqa: E402
from dlo_ros.recording.replay import read_recording  # noqa: E402
from dlo_ros.scene import load_scene  # noqa: E402
from dlo_ros.solver import ShapeSolver  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
MAGIC_HEADER_BYTES = 12  # "RRF2", the writer's version (4 bytes), the encoding options (4 bytes)


def replay(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    env["DLO_NO_COMPILE"] = "1"
    return subprocess.run([sys.executable, "-m", "dlo_ros.cli", "replay", *args],
                          capture_output=True, text=True, timeout=timeout, cwd=REPO, env=env)


def assert_refused(path: Path, says: str = "") -> str:
    """`dlo replay PATH` (a subprocess) and `dlo replay PATH --resolve` (in this process, the same
    code): exit 2, nothing on stdout, one stderr line naming the file; returns that line."""
    import contextlib
    import io

    from dlo_ros.cli import main

    done = replay(str(path))
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()) as out:
        code = main(["replay", str(path), "--resolve"])
    runs = ((done.returncode, done.stdout, done.stderr), (code, out.getvalue(), err.getvalue()))
    for rc, stdout, stderr in runs:
        lines = stderr.strip().splitlines()
        assert rc == 2, (path, rc, stdout, stderr)
        assert "Traceback" not in stderr and stdout == "", stdout + stderr
        assert len(lines) == 1 and lines[0].startswith("dlo: error: "), lines
        assert str(path) in lines[0], lines
        assert says.lower() in lines[0].replace(str(path), "FILE").lower(), lines[0]
    return lines[0]


# ---- recordings written for real ----------------------------------------------------------------
def _write(path: Path, updates: int, flush_each: bool) -> list:
    scene = load_scene("default_cable")
    solver = ShapeSolver(scene.problem, scene.options, compile="off")
    poses = {g.name: (g.pose.position, g.pose.orientation) for g in scene.problem.grips}
    r = solver.solve(poses, warm=False)
    assert r.status == "ok"
    logged = []
    with Recorder(rrd=path, queue_size=4096) as rec:
        rec.log_scene(scene, solver=solver)
        for k in range(updates):
            one = replace(r, points=r.points + 1e-3 * k)
            rec.log_targets(poses, update=k)
            rec.log_update(one, update=k, problem=scene.problem, warm=k > 0)
            logged.append(one)
            if flush_each or k % 500 == 499:
                rec.flush(60)
    assert rec.errors == 0 and rec.dropped == 0, rec.last_error
    return logged


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """12 updates, flushed one by one: the results are spread over many rrd messages."""
    path = tmp_path_factory.mktemp("small") / "small.rrd"
    _write(path, 12, flush_each=True)
    return path


def message_ends(data: bytes) -> list[int]:
    """Byte offsets where the rrd messages end (a 16-byte header: kind, length; then the payload),
    up to and including the end message (kind 0)."""
    off, ends = MAGIC_HEADER_BYTES, []
    while off + 16 <= len(data):
        kind, length = struct.unpack_from("<QQ", data, off)
        off += 16 + length
        ends.append(off)
        if kind == 0:
            break
    return ends


# ---- files that are not recordings --------------------------------------------------------------
def test_crafted_files_are_refused_in_one_line(tmp_path, small):
    real = small.read_bytes()
    rng = np.random.default_rng(35)
    cases = {
        "magic_then_random.rrd": b"RRF2" + rng.bytes(4000),
        "header_then_garbage.rrd": real[:MAGIC_HEADER_BYTES] + rng.bytes(4000),
        "header_then_garbled_message.rrd": real[:MAGIC_HEADER_BYTES] + struct.pack("<QQ", 2, 3000)
        + rng.bytes(3000),
        "empty.rrd": b"",
        "text.rrd": b"not a recording\n",
        "header_only.rrd": real[:MAGIC_HEADER_BYTES],
    }
    ends = message_ends(real)
    garbled = bytearray(real)  # a chunk's payload overwritten in the middle of a real recording
    start = ends[len(ends) // 2] + 16
    garbled[start:start + 200] = rng.bytes(200)
    cases["garbled_chunk.rrd"] = bytes(garbled)
    for name, data in cases.items():
        path = tmp_path / name
        path.write_bytes(data)
        assert_refused(path)


def test_a_fifo_is_refused_without_blocking(tmp_path):
    fifo = tmp_path / "pipe.rrd"
    os.mkfifo(fifo)
    assert_refused(fifo, says="not a regular file")  # replay() times out (fails) if open blocks


def test_a_directory_is_refused(tmp_path):
    folder = tmp_path / "folder.rrd"
    folder.mkdir()
    assert_refused(folder, says="directory")


def test_an_oversized_file_is_refused_before_reading(tmp_path):
    from dlo_ros.recording.rrd_file import LIMITS

    big = tmp_path / "big.rrd"
    with open(big, "wb") as f:  # sparse: no disk used
        f.write(b"RRF2")
        f.truncate(LIMITS["file_bytes"] + 1)
    assert_refused(big, says=f"at most {LIMITS['file_bytes']}")


# ---- recordings that are rerun files, but not dlo_ros's -----------------------------------------
def _rerun_file(path: Path, application: str, log) -> Path:
    import rerun as rr

    rec = rr.RecordingStream(application)
    rec.save(str(path))
    log(rr, rec)
    rec.flush(timeout_sec=10)
    rec.disconnect()
    return path


def test_a_recording_from_another_program_is_refused(tmp_path):
    path = _rerun_file(tmp_path / "other.rrd", "someone_else",
                       lambda rr, rec: rec.log("points", rr.Points3D([[0, 0, 0], [1, 1, 1]])))
    assert_refused(path, says="not a dlo_ros recording")


CRAFT = """
import sys
import numpy as np
import rerun as rr
from dlo_ros.recording import scene_yaml
from dlo_ros.scene import load_scene

n = 51
good = {"status": "ok", "message": "", "warm_started": False, "s": np.linspace(0, 1, n),
        "points": np.zeros(3 * n)}
cases = {
    "points_as_text": {**good, "points": ["a"] * (3 * n)},
    "points_nan": {**good, "points": np.full(3 * n, np.nan)},
    "points_not_triples": {**good, "points": np.zeros(3 * n + 1)},
    "status_as_number": {**good, "status": 3.0},
    "poses_miscounted": {**good, "target_names": ["left", "right"], "target_poses": np.zeros(9)},
}
rec = rr.RecordingStream("dlo_ros")
rec.save(sys.argv[1])
rec.log("scene/yaml", rr.TextDocument(scene_yaml(load_scene("default_cable"))),
        rr.AnyValues(scene_name="default_cable", solver="ShapeSolver"), static=True)
rec.set_time("update", sequence=0)
rec.log("data/result", rr.AnyValues(**cases[sys.argv[2]]))
rec.flush(timeout_sec=10)
rec.disconnect()
"""


def test_wrong_dtypes_and_nan_in_a_result_are_refused(tmp_path):
    """A dlo_ros-looking recording (a real scene) whose data/result has the wrong types or values;
    each file is written by its own process (rerun keeps the first type it saw for a name)."""
    says = {"points_as_text": "data/result column points", "points_nan": "NaN",
            "points_not_triples": "multiple of 3", "status_as_number": "data/result column status",
            "poses_miscounted": "7 per grip"}
    for case, text in says.items():
        path = tmp_path / f"{case}.rrd"
        done = subprocess.run([sys.executable, "-c", CRAFT, str(path), case], capture_output=True,
                              text=True, timeout=120, cwd=REPO)
        assert done.returncode == 0 and "Warning" not in done.stderr, done.stderr
        assert_refused(path, says=text)


# ---- truncated recordings -----------------------------------------------------------------------
def test_a_truncated_recording_replays_the_updates_before_the_cut(tmp_path, small):
    whole = read_recording(small)
    assert [r.update for r in whole.results] == list(range(12)) and not whole.truncated
    data = small.read_bytes()
    ends = message_ends(data)
    cuts = sorted({ends[i] - 1 for i in range(3, len(ends) - 1, max(1, len(ends) // 9))}
                  | {ends[-2] + 20, len(data) - 1})  # ... inside the end message / its footer
    counts = []
    for cut in cuts:
        path = tmp_path / f"cut_{cut}.rrd"
        path.write_bytes(data[:cut])
        rec = read_recording(path)
        assert rec.truncated and rec.complete_bytes <= cut < rec.file_bytes + 1, cut
        n = len(rec.results)
        assert rec.scene_name == "default_cable" or n == 0
        for got, want in zip(rec.results, whole.results[:n]):
            assert got.update == want.update and got.status == want.status
            assert np.array_equal(got.points, want.points)  # exact: float64 as recorded
            assert got.targets.keys() == want.targets.keys()
        counts.append(n)
    assert counts == sorted(counts), counts  # a later cut never loses an update
    assert counts[-1] == 12 and any(0 < n < 12 for n in counts), counts
    # the command line: the updates before the cut re-solve, and one note says the file ends early
    middle = next(c for c, n in zip(cuts, counts) if 0 < n < 12)
    done = replay(str(tmp_path / f"cut_{middle}.rrd"), "--resolve", "--json", timeout=600)
    n = counts[cuts.index(middle)]
    notes = [line for line in done.stderr.splitlines() if line.startswith("dlo replay: note:")]
    assert len(notes) == 1 and "ends early" in notes[0], done.stderr
    assert f"read {n} updates" in notes[0], notes
    assert "Traceback" not in done.stderr
    assert done.returncode in (0, 1) and f'"count": {n}' in done.stdout, done.stdout + done.stderr


# ---- memory -------------------------------------------------------------------------------------
PEAK = """
import resource, sys
import pyarrow, rerun.chunk
import dlo_ros.cli, dlo_ros.recording.replay
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
code = dlo_ros.cli.main(["replay", sys.argv[1]])
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(code, (after - before) // 1024)
"""


def test_checking_a_long_recording_does_not_keep_its_updates(tmp_path):
    """`dlo replay FILE` (no display: it checks the file and explains) on 6000 updates: the peak
    memory above the imports is about that for 300 updates (before: +208 MB for 6000 updates)."""
    growth = {}
    for n in (300, 6000):
        path = tmp_path / f"long_{n}.rrd"
        _write(path, n, flush_each=False)
        env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
        done = subprocess.run([sys.executable, "-c", PEAK, str(path)], capture_output=True,
                              text=True, timeout=300, cwd=REPO, env=env)
        code, mb = done.stdout.strip().splitlines()[-1].split()
        assert code == "0", done.stdout + done.stderr
        growth[n] = int(mb)
    assert growth[6000] < growth[300] + 40, growth  # 14 MB more file: no growth per update


def test_count_and_data_limits_refuse_in_one_line(small, monkeypatch):
    """The row and kept-data limits, lowered below what the 12-update recording holds."""
    from dlo_ros.recording import rrd_file
    from dlo_ros.recording.replay import RecordingError, check_recording

    assert len(read_recording(small, details=False).results) == 12
    monkeypatch.setitem(rrd_file.LIMITS, "updates", 11)
    with pytest.raises(RecordingError, match=r": more than 11 rows") as err:
        read_recording(small)
    assert str(small) in str(err.value) and "\n" not in str(err.value)
    monkeypatch.setitem(rrd_file.LIMITS, "updates", 12)
    monkeypatch.setitem(rrd_file.LIMITS, "kept_bytes", 12 * 1024)  # 12 rows of 1 KiB, and numbers
    with pytest.raises(RecordingError, match=r"more than 12288 bytes of data"):
        read_recording(small, details=False)
    assert check_recording(small).updates == 12  # keeps nothing: the limit is per chunk there
    monkeypatch.setitem(rrd_file.LIMITS, "entities", 3)
    with pytest.raises(RecordingError, match=r"more than 3 entities"):
        check_recording(small)
