"""Hostile and broken scene files through the real CLI (a subprocess): every one is refused with one
line naming the file and the key, exit code 2, no traceback, in bounded time and memory; and messages
never echo a file's content from outside the scene format."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dlo_ros import cli
from dlo_ros.scene import LIMITS, SceneError, load_scene, scene_from_dict, scene_to_dict
from support.cli import assert_one_line_error

ROOT = Path(__file__).resolve().parents[2]
GOOD_TAIL = "grips:\n  - {name: a, s: 0.0, position: [0, 0, 0]}\n"
GOOD_HEAD = "string: {length: 1.0, bend_stiffness: 0.02}\n"
MB = 1 << 20


def run_solve(path: os.PathLike | str, *extra: str, timeout: float = 60.0):
    """``python -m dlo_ros.cli solve PATH``: (return code, stderr, wall s, peak RSS of the child in MB)."""
    # a wrapper process whose only child is the CLI measures that child's peak RSS (this process's
    # RUSAGE_CHILDREN is the largest of every child the test session ever waited for)
    wrapper = ("import resource, subprocess, sys\n"
               "p = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
               "sys.stderr.write(p.stderr)\n"
               "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)\n"
               "sys.exit(p.returncode)\n")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", wrapper, sys.executable, "-m", "dlo_ros.cli", "solve", str(path),
                           *extra], cwd=ROOT, capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "DLO_NO_COMPILE": "1"})
    wall = time.perf_counter() - t0
    peak = int(proc.stdout.strip().splitlines()[-1]) / 1024
    return proc.returncode, proc.stderr, wall, peak


def assert_refused(path, *words: str, **kwargs) -> str:
    code, err, wall, _ = run_solve(path, **kwargs)
    assert_one_line_error(code, err, words)
    return err


def billion_laughs(levels: int = 9, width: int = 9) -> str:
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    for i in range(1, levels + 1):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * width) + "]")
    lines.append(f"string: {{length: 1, bend_stiffness: *a{levels}}}")
    return "\n".join(lines) + "\n"


# ---- 1. what a scene may cost is bounded before anything is expanded --------------------------------
def test_billion_laughs_is_refused_fast_and_small(tmp_path):
    f = tmp_path / "lol.yaml"
    f.write_text(billion_laughs())
    assert f.stat().st_size < 1024
    code, err, wall, peak = run_solve(f)
    assert code == 2 and "Traceback" not in err, err
    assert f"more than {LIMITS['nodes']} YAML nodes with aliases expanded" in err, err
    assert str(f) in err and "a5:" in err, err  # the key (anchor) whose expansion crossed the limit
    # before: > 3 GB and a MemoryError traceback.  A bare `dlo solve` of a good scene peaks at ~260 MB.
    assert wall < 15.0 and peak < 400, (wall, peak)


def test_alias_count_is_limited(tmp_path):
    f = tmp_path / "aliases.yaml"
    f.write_text("x: &x 1\n" + GOOD_HEAD + "description: [" + ", ".join(["*x"] * (LIMITS["aliases"] + 1)) + "]\n"
                 + GOOD_TAIL)
    assert_refused(f, f"more than {LIMITS['aliases']} YAML aliases", "description", f"{f}:3")


def test_recursive_alias_is_refused(tmp_path):
    f = tmp_path / "recursive.yaml"
    f.write_text(GOOD_HEAD + "description: &r [1, *r]\n" + GOOD_TAIL)
    assert_refused(f, "recursive structure", "description[1]")


def test_a_few_aliases_still_work(tmp_path):
    f = tmp_path / "ok.yaml"
    f.write_text("string: {length: 1.0, bend_stiffness: &k 0.02, twist_stiffness: *k}\n"
                 "grips:\n  - {name: a, s: 0.0, position: &p [0, 0, 0.4]}\n  - {name: b, s: 1.0, position: [0.6, 0, 0.4]}\n")
    scene = load_scene(f)
    assert float(scene.problem.string.twist_stiffness.values[0]) == 0.02


def test_big_file_is_refused_before_parsing(tmp_path):
    # the 3.7 MB valid scene with 100,000 point loads that used to take the CLI past 3 GB
    f = tmp_path / "loads.yaml"
    f.write_text(GOOD_HEAD + GOOD_TAIL.replace("s: 0.0", "s: 0.0") + "loads:\n"
                 + "".join(f"  - {{s: {0.1 + 0.8 * i / 100000:.6f}, force: [0, 0, -1e-6]}}\n" for i in range(100_000)))
    assert f.stat().st_size > 3 * MB
    err = assert_refused(f, f"{f}: the file has {f.stat().st_size} bytes, a scene file at most {LIMITS['file_bytes']}")
    assert "Limits" in err


@pytest.mark.parametrize("key, item, limit", [
    ("loads", "  - {s: 0.5, force: [0, 0, -0.001]}\n", "loads"),
    ("obstacles", "  - {type: sphere, center: [0, 3, 0], radius: 0.1}\n", "obstacles"),
    ("relative_positions", "  - {s_a: 0.1, s_b: 0.2, offset: [0.05, 0, 0]}\n", "relative_positions"),
])
def test_list_lengths_are_limited(tmp_path, key, item, limit):
    n = LIMITS[limit] + 1
    f = tmp_path / f"{key}.yaml"
    f.write_text(GOOD_HEAD + GOOD_TAIL + f"{key}:\n" + item * n)
    assert_refused(f, f"{key}: {n} items, at most {LIMITS[limit]} are allowed", f"(in {f}:4)")


def test_grips_and_profile_rows_are_limited():
    d = scene_to_dict(load_scene("default_cable"))
    many = dict(d, grips=[dict(d["grips"][0], name=f"g{i}", s=i / 100) for i in range(LIMITS["grips"] + 1)])
    with pytest.raises(SceneError, match=rf"^grips: {LIMITS['grips'] + 1} items, at most"):
        scene_from_dict(many)
    rows = LIMITS["profile_rows"] + 1
    table = dict(d, string=dict(d["string"], bend_stiffness={"table": [[i / rows, 0.02] for i in range(rows)]}))
    with pytest.raises(SceneError, match=r"^string\.bend_stiffness\.table: 1001 items"):
        scene_from_dict(table)


def test_long_strings_are_limited(tmp_path):
    f = tmp_path / "long.yaml"
    f.write_text(GOOD_HEAD + f"description: '{'x' * (LIMITS['scalar_chars'] + 1)}'\n" + GOOD_TAIL)
    assert_refused(f, "description: over a limit: a value of 10001 characters", f"{f}:2")
    f.write_text(GOOD_HEAD + f"frame_id: {'w' * (LIMITS['frame_id_chars'] + 1)}\n" + GOOD_TAIL)
    assert_refused(f, "frame_id: 257 characters, at most 256", f"{f}:2")
    f.write_text(GOOD_HEAD + "grips:\n  - {name: \"a\\e[31mred\\nINFO fake\", s: 0.0, position: [0, 0, 0]}\n")
    err = assert_refused(f, "grips[0].name: must be printable text without control characters")
    assert "\x1b" not in err


# ---- 2. tracebacks -> one-line errors ----------------------------------------------------------------
@pytest.mark.parametrize("where, text, key", [
    ("string.length", "string: {length: 1" + "0" * 400 + ", bend_stiffness: 0.02}\n" + GOOD_TAIL, "string.length"),
    ("solver.order", GOOD_HEAD + GOOD_TAIL + "solver: {order: 1" + "0" * 400 + "}\n", "solver.order"),
    ("block", GOOD_HEAD + GOOD_TAIL + "solver:\n  order: " + "9" * 5000 + "\n", "solver.order"),
])
def test_huge_integers(tmp_path, where, text, key):
    f = tmp_path / "int.yaml"
    f.write_text(text)
    err = assert_refused(f, f"{key}: over a limit: an integer with", str(f))
    assert "0" * 40 not in err and "9" * 40 not in err  # the number is not echoed


def test_integer_beyond_float_range_names_its_key():
    d = scene_to_dict(load_scene("default_cable"))
    d["string"]["length"] = 10 ** 400  # a dict, not a file: no digit limit, float() overflows
    with pytest.raises(SceneError, match=r"^string\.length: out of range: an integer with 401 digits"):
        scene_from_dict(d)


def test_deep_flow_nesting(tmp_path):
    f = tmp_path / "deep.yaml"
    f.write_text("string: " + "[" * 10_000 + "]" * 10_000 + "\n")
    assert_refused(f, f"nested more than {LIMITS['depth']} levels deep", f"{f}:1", "string[0]")


def test_deep_block_nesting(tmp_path):
    f = tmp_path / "deepblock.yaml"
    f.write_text("string:\n" + "".join("  " * (i + 1) + f"k{i}:\n" for i in range(300)))
    assert_refused(f, f"nested more than {LIMITS['depth']} levels deep", "string.k0.k1")


def test_directory_fifo_and_device(tmp_path):
    assert_refused(tmp_path, f"{tmp_path}: is a directory, not a scene file")
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)
    # a plain open() would block forever on a FIFO without a writer: the timeout guards the test
    assert_refused(fifo, f"{fifo}: not a regular file", timeout=20)
    assert_refused("/dev/zero", "/dev/zero: not a regular file", timeout=20)


def test_unreadable_file(tmp_path, monkeypatch, capsys):
    # the tests run as root, who may read anything: simulate EACCES where the scene file is opened
    f = tmp_path / "secret.yaml"
    f.write_text(GOOD_HEAD + GOOD_TAIL)
    real_open = os.open

    def deny(path, *args, **kwargs):
        if os.fspath(path) == str(f):
            raise PermissionError(13, "Permission denied", str(f))
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(os, "open", deny)
    assert cli.main(["solve", str(f)]) == 2
    err = capsys.readouterr().err
    assert err == f"dlo: error: {f}: cannot open the scene file: Permission denied\n"


def test_unreadable_file_as_another_user(tmp_path):
    """The real thing when the tests run as root and user 'nobody' can run this interpreter."""
    if os.geteuid() != 0:
        pytest.skip("needs root to drop to another user")
    f = tmp_path / "secret.yaml"
    f.write_text(GOOD_HEAD + GOOD_TAIL)
    f.chmod(0o600)
    tmp_path.chmod(0o755)
    try:
        probe = subprocess.run([sys.executable, "-c", "import dlo_ros.cli"], cwd=ROOT, capture_output=True,
                               user=65534, timeout=60)
    except OSError:  # e.g. the interpreter itself is not executable for 'nobody'
        probe = None
    if probe is None or probe.returncode != 0:
        pytest.skip("user nobody cannot import dlo_ros here")
    proc = subprocess.run([sys.executable, "-m", "dlo_ros.cli", "solve", str(f)], cwd=ROOT, capture_output=True,
                          text=True, user=65534, timeout=60)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr == f"dlo: error: {f}: cannot open the scene file: Permission denied\n"


# ---- 5. messages name the file and the key, never another file's content --------------------------------
def test_other_files_are_not_echoed(tmp_path):
    secret = "hunter2-s3cr3t"
    cases = {
        "passwd": f"root:x:0:0:{secret}:/root:/bin/bash\ndaemon:x:1:1::/usr/sbin:/usr/sbin/nologin\n",
        "config": f"api_token: {secret}\nuser: admin\n",
        "yaml_error": f"password: {secret}\n  bad indent: {secret}\n",
        "tab": f"key: {secret}\n\tx: {secret}\n",
        "scene_value": GOOD_HEAD.replace("1.0", f"'{secret}-and-much-more-text-than-forty-characters'") + GOOD_TAIL,
        "unknown_key": GOOD_HEAD + GOOD_TAIL + f"{secret}: 1\n",
    }
    for name, text in cases.items():
        f = tmp_path / f"{name}.yaml"
        f.write_text(text)
        err = assert_refused(f, str(f))
        assert secret not in err, (name, err)
    code, err, _, _ = run_solve("/etc/passwd")
    first = Path("/etc/passwd").read_text().splitlines()[0]
    assert code == 2 and first not in err and "Traceback" not in err, err


def test_limits_are_documented():
    doc = (ROOT / "msg_docs" / "scene_format.md").read_text()
    section = doc[doc.index("## Limits"):]
    for name, value in LIMITS.items():
        assert re.search(rf"`{name}`[^\n]*\b{value:,}\b".replace(",", "[, ]?"), section) or \
            re.search(rf"`{name}`[^\n]*\b{value}\b", section), f"LIMITS[{name!r}] = {value} is not in scene_format.md"


def test_long_paths_are_not_cut(tmp_path):
    """Paths are escaped for messages, never truncated: the scene's default name comes from the file's stem."""
    deep = tmp_path / ("a" * 200) / ("b" * 40)
    deep.mkdir(parents=True)
    f = deep / "my_scene.yaml"
    f.write_text(GOOD_HEAD + GOOD_TAIL)
    scene = load_scene(f)
    assert scene.name == "my_scene" and scene.source == str(f)
