"""The node's command line, params files and user-controlled strings.

* Every ``dlo ...`` command line in README.md and msg_docs/ parses (``dlo node`` lines: the node's own
  checks, which run before rclpy); the README's ``dlo node --scene default_cable`` really starts a node.
* A bad params file or ``-p`` value stops start-up with one line naming the file and parameter, exit 2.
* Strings that reach logs and /diagnostics are escaped and capped; an oversized frame_id is rejected;
  bad-query warnings are throttled; a parameter named '' is refused.  Real DDS, own ROS_DOMAIN_ID.
"""
from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dlo_ros import cli
from dlo_ros.node import params as P
from dlo_ros.node.client import DloClient, allocate_domain_id, ros_env
from dlo_ros.node.validation import FRAME_ID_LIMIT, TEXT_LIMIT, TargetError, check_frame, safe_text
from support.node import TEST_MODEL, clean_node, node_args

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", *sorted((ROOT / "msg_docs").glob("*.md"))]
SHIPPED_PARAMS = str(ROOT / "config" / "dlo_node.yaml")


# ---- the helper --------------------------------------------------------------------------------------------
def test_safe_text_escapes_and_caps():
    assert safe_text("world") == "world"
    assert safe_text("a\x1b[31mred\x1b[0m\nINFO fake\r\t\u202e") == "a\\x1b[31mred\\x1b[0m\\nINFO fake\\r\\t\\u202e"
    long = safe_text("x" * 10_000_000)
    assert len(long) == TEXT_LIMIT and long.endswith("…")
    escaped = safe_text("\x1b" * 1000)
    assert len(escaped) <= TEXT_LIMIT and "\x1b" not in escaped
    assert safe_text("é ü 中文") == "é ü 中文"  # printable text is kept as is


def test_frame_id_size_is_checked_before_anything_else():
    with pytest.raises(TargetError, match=rf"header.frame_id has 1000000 characters \(at most {FRAME_ID_LIMIT}\)") as e:
        check_frame("m" * 1_000_000, "world", "grips/left/target")
    assert e.value.kind == "frame" and len(str(e.value)) < 200
    with pytest.raises(TargetError) as e:
        check_frame("map\x1b[2J\nFAKE", "world", "w")
    assert "\x1b" not in str(e.value) and "\n" not in str(e.value) and "map\\x1b[2J\\nFAKE" in str(e.value)


def test_empty_parameter_name_is_refused():
    assert P.check_live("", 1.0, None) == "a parameter name must not be empty"
    assert P.unknown_reason("") == "a parameter name must not be empty"


# ---- 3. every documented `dlo` command line parses -----------------------------------------------------------
def documented_command_lines() -> list[tuple[str, str]]:
    """(document, command) for every `dlo ...` / `python -m dlo_ros.node ...` line in a fenced code block
    (after an optional `bash scripts/dlo-env run` / `scripts/dlo-env run`), comments and descriptions
    after two spaces stripped."""
    found = []
    for doc in DOCS:
        inside = False
        for line in doc.read_text().splitlines():
            if line.startswith("```"):
                inside = not inside
                continue
            if not inside:
                continue
            cmd = re.sub(r"^\s*(bash\s+)?scripts/dlo-env run\s+", "", line)
            cmd = re.sub(r"\s+#.*$", "", cmd).strip()
            cmd = re.split(r"\s{2,}", cmd)[0]  # recording.md: `dlo replay FILE.rrd   what it does`
            if cmd.startswith(("dlo ", "python -m dlo_ros.node ")) or cmd in ("dlo", "python -m dlo_ros.node"):
                found.append((doc.name, cmd))
    return found


def concrete(cmd: str, params_file: str) -> list[str]:
    """A synopsis line (``dlo node [--params-file FILE] [--scene NAME] [--ros-args ...]``) as a command
    with every optional part given; a concrete line as it is."""
    cmd = re.sub(r"\{([^,}]+),[^}]*\}", r"\1", cmd)  # {chebyshev,fourier} -> chebyshev
    cmd = cmd.replace("[", " ").replace("]", " ")
    subs = {"SCENE": "default_cable", "NAME": "default_cable", "NAME_OR_PATH": "default_cable",
            "FILE.rrd": "run.rrd", "N": "16", "M": "0.001", "PNG": "shot.png", "ADDR": "127.0.0.1:9876",
            "...": "-p use_tf:=false", "…": "-p use_tf:=false"}
    tokens = []
    for t in shlex.split(cmd):
        if t == "FILE":
            t = params_file if "node" in cmd else "run.rrd"
        tokens.extend(shlex.split(subs.get(t, t)))
    return tokens


def test_documented_command_lines_parse():
    lines = documented_command_lines()
    node_lines = [c for _, c in lines if c.startswith(("dlo node", "python -m dlo_ros.node"))]
    # the README's own example, and the synopses of cli.md and node.md, at least
    assert "dlo node --scene default_cable" in node_lines, lines
    assert len(node_lines) >= 3, node_lines
    for doc, cmd in lines:
        tokens = concrete(cmd, SHIPPED_PARAMS)
        if cmd.startswith("python -m dlo_ros.node"):
            tokens = ["dlo", "node", *tokens[3:]]
        if tokens[1] == "node":
            prepared = P.prepare_node_args(tokens[2:], SHIPPED_PARAMS)  # raises ParamsError / SystemExit
            assert prepared.ros_args[0] == "dlo_node" and prepared.scene, (doc, cmd)
        else:
            try:
                cli.build_parser().parse_args(tokens[1:])
            except SystemExit as exc:  # pragma: no cover - the failure message
                pytest.fail(f"{doc}: `{cmd}` ({tokens}) does not parse: exit {exc.code}")


def run_cli(*args: str, timeout: float = 60.0, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dlo_ros.cli", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, **(env or {})})


def test_readme_node_command_checks_without_ros():
    proc = run_cli("node", "--scene", "default_cable", "--check")
    assert proc.returncode == 0, proc.stderr
    assert "scene 'default_cable'" in proc.stdout and "the node would start" in proc.stdout
    help_ = run_cli("node", "--help")
    assert help_.returncode == 0 and "--params-file" in help_.stdout and "--ros-args" in help_.stdout


def test_readme_node_command_starts_a_node(tmp_path):
    """`dlo node --scene default_cable` (plus test settings after --ros-args) publishes a shape and stops
    cleanly on SIGINT."""
    log = tmp_path / "node.log"
    with allocate_domain_id() as lease, open(log, "wb") as out:
        proc = subprocess.Popen(
            [sys.executable, "-m", "dlo_ros.cli", "node", "--scene", "default_cable", "--ros-args",
             "-p", "compile:=off", "-p", f"solver.model:={TEST_MODEL}"],
            cwd=ROOT, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
            env=ros_env(lease.domain_id), start_new_session=True)
        try:
            with DloClient(lease.domain_id, client_name="readme_client") as client:
                first = None
                deadline = time.monotonic() + 60
                while first is None and proc.poll() is None and time.monotonic() < deadline:
                    first = client.wait_for_path(0.25)
                assert first is not None, log.read_text()
        finally:
            proc.send_signal(signal.SIGINT)
            try:
                code = proc.wait(20)
            except subprocess.TimeoutExpired:  # pragma: no cover
                os.killpg(proc.pid, signal.SIGKILL)
                code = proc.wait(5)
    text = log.read_text()
    assert code == 0, text
    assert "Traceback" not in text and "scene 'default_cable'" in text, text


# ---- 4. bad params files and -p values stop start-up ----------------------------------------------------------
def params_yaml(body: str) -> str:
    return "/**:\n  ros__parameters:\n" + "".join(f"    {ln}\n" for ln in body.splitlines())


BAD_PARAMS = [
    # (file name, content or None for a directory, words in the one-line error)
    ("syntax.yaml", "/**:\n  ros__parameters:\n    scene: [default_cable\n", ["syntax.yaml:", "YAML syntax error"]),
    ("list.yaml", "- scene\n- default_cable\n", ["list.yaml: a ROS parameters file must be a mapping", "got a list"]),
    ("scalar.yaml", "just text\n", ["scalar.yaml: a ROS parameters file must be", "got a str"]),
    ("empty.yaml", "", ["empty.yaml: a ROS parameters file must be", "got an empty file"]),
    ("no_ros_parameters.yaml", "/**:\n  scene: default_cable\n",
     ["no_ros_parameters.yaml:1: node entry '/**' must be {ros__parameters: {...}}"]),
    ("typo.yaml", params_yaml("scene: default_cable\nsolver:\n  modle: full"),
     ["typo.yaml:5: parameter solver.modle: not a parameter of the dlo node; did you mean 'solver.model'?"]),
    ("frame.yaml", params_yaml("frame_id: /"), ["frame.yaml:3: parameter frame_id: '/' is not a usable frame id"]),
    ("type.yaml", params_yaml("diagnostics_period: fast"),
     ["type.yaml:3: parameter diagnostics_period: expected a number, got the string 'fast'"]),
    ("range.yaml", params_yaml("diagnostics_period: 0.0"),
     ["range.yaml:3: parameter diagnostics_period: must be >= 0.05, got 0.0"]),
    ("model.yaml", params_yaml("solver:\n  model: fastest"), ["model.yaml:4: parameter solver.model: must be empty, auto"]),
    ("lol.yaml", "a: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n" + "".join(
        f"b{i}: &b{i} [" + ", ".join([f"*{'a' if i == 0 else f'b{i - 1}'}"] * 10) + "]\n" for i in range(6)),
     ["lol.yaml:", "over a limit: more than 100000 YAML nodes"]),
    ("dir.yaml", None, ["dir.yaml: is a directory"]),
]


@pytest.mark.parametrize("name, content, words", BAD_PARAMS, ids=[c[0] for c in BAD_PARAMS])
def test_bad_params_file_stops_start_up(tmp_path, name, content, words):
    f = tmp_path / name
    if content is None:
        f.mkdir()
    else:
        f.write_text(content)
    proc = run_cli("node", "--params-file", str(f), "--ros-args", "-p", "compile:=off", timeout=30)
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr and "Failed to parse global arguments" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dlo_node: error: params file "), proc.stderr
    for w in words:
        assert w.replace("syntax.yaml:", str(f) + ":") in proc.stderr or w in proc.stderr, (w, proc.stderr)
    assert str(f) in proc.stderr


@pytest.mark.parametrize("args, words", [
    (["-p", "frame_id:=/"], "--ros-args -p: parameter frame_id: '/' is not a usable frame id"),
    (["-p", "frame_id:=" + "f" * 300], "parameter frame_id: 300 characters, at most 256"),
    (["-p", "use_tff:=false"], "parameter use_tff: not a parameter of the dlo node; did you mean 'use_tf'?"),
    (["-p", ":=1"], "parameter '': a parameter name must not be empty"),
    (["-p", "compile:=fast"], "parameter compile: must be one of background, blocking, cached, off"),
    (["--params-file", "/nonexistent/p.yaml"], "--ros-args --params-file /nonexistent/p.yaml: no such file"),
])
def test_bad_ros_args_stop_start_up(args, words):
    proc = run_cli("node", "--ros-args", *args, timeout=30)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.startswith("dlo_node: error: ") and words in proc.stderr, proc.stderr


def test_params_of_other_nodes_are_left_alone(tmp_path):
    f = tmp_path / "shared.yaml"
    f.write_text("/**:\n  ros__parameters:\n    use_sim_time: false\n"
                 "camera:\n  ros__parameters:\n    exposure: 3\n"
                 "/cell/dlo:\n  ros__parameters:\n    scene: default_cable\n    frame_id: map\n")
    prepared = P.prepare_node_args(["--params-file", str(f)])
    assert prepared.values == {"use_sim_time": False, "scene": "default_cable", "frame_id": "map"}
    with pytest.raises(P.ParamsError, match="parameter frame_idd"):
        P.prepare_node_args(["--params-file", str(f), "--ros-args", "-r", "__node:=cable", "-p", "frame_idd:=x"])


def test_scene_pointing_at_another_file_is_not_echoed(tmp_path):
    secret = "hunter2-s3cr3t"
    f = tmp_path / "private.conf"
    f.write_text(f"token: {secret}\n[section]\npassword = {secret}\n")
    for args in (["--scene", str(f)], ["--ros-args", "-p", f"scene:={f}"]):
        proc = run_cli("node", *args, "--check", timeout=30)
        assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
        assert str(f) in proc.stderr and secret not in proc.stderr, proc.stderr


# ---- 6, 7. strings in logs and diagnostics; throttled query warnings; parameter '' ---------------------------
NODE_ARGS = node_args("diagnostics_period:=0.2", "warn_throttle:=30.0")
Q = (0.0, 0.0, 0.0, 1.0)
LEFT, RIGHT = ((0.0, 0.0, 0.4), Q), ((0.5, 0.0, 0.42), Q)


def test_node_strings_are_escaped_capped_and_throttled(tmp_path):
    with clean_node(*NODE_ARGS, log_path=tmp_path / "node.log") as (proc, cl):
        # a 1 MB frame_id (the reported 10 MB one went into /diagnostics every second): refused by the
        # message's size before it is read
        cl.publish_grip("right", *RIGHT, frame_id="m" * 1_000_000)
        got = cl.wait_for_diagnostics(lambda v, st: v.get("errors.size") == "1", 20.0)
        assert got is not None, proc.output()
        assert "message of 1000076 bytes is over the limit of 4096 bytes" in got[0]["last error"], got[0]["last error"]
        # a frame_id within the message limit but over 256 characters
        cl.publish_grip("right", *RIGHT, frame_id="m" * 1000)
        got = cl.wait_for_diagnostics(lambda v, st: v.get("errors.frame") == "1", 20.0)
        assert got is not None, proc.output()
        values, status = got
        assert "header.frame_id has 1000 characters (at most 256)" in values["last error"], values["last error"]
        assert all(len(v) <= 5 * TEXT_LIMIT for v in values.values()), max(map(len, values.values()))
        assert len(status.message) <= TEXT_LIMIT

        # log injection: ANSI escapes and a newline in a frame_id are escaped in the log and the diagnostics
        cl.publish_grip("right", *RIGHT, frame_id="map\x1b[31m\nFAKE [ERROR] injected")
        got = cl.wait_for_diagnostics(lambda v, st: v.get("errors.frame") == "2", 20.0)
        assert got is not None, proc.output()
        assert "map\\x1b[31m\\nFAKE [ERROR] injected" in got[0]["last error"], got[0]["last error"]

        # bad queries: each answered with an empty plan and counted, but warned about once per warn_throttle
        for _ in range(5):
            points, _ = cl.query(LEFT, RIGHT, frame_id="elsewhere")
            assert len(points) == 0
        got = cl.wait_for_diagnostics(lambda v, st: v.get("queries failed") == "5", 20.0)
        assert got is not None, proc.output()

        # a parameter named '' is refused
        (ok, reason), = cl.set_parameters({"": 1.0})
        assert not ok and "must not be empty" in reason, reason
    log = (tmp_path / "node.log").read_text()
    assert "\x1b" not in log, "an escape sequence reached the log"
    assert "\nFAKE" not in log
    assert max(len(line) for line in log.splitlines()) < 2000
    assert log.count("query_shape: empty plan") == 1, log
    assert log.count("rejected target (frame)") == 1, log  # warn_throttle 30 s: the second one is throttled


def test_readme_python_examples_run():
    """Every ```python block of the README runs as written (interpreted derivatives), in a fresh interpreter."""
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), flags=re.S)
    assert blocks, "no python example in the README"
    env = dict(os.environ, DLO_NO_COMPILE="1")
    for code in blocks:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600, env=env,
                              cwd=ROOT)
        assert done.returncode == 0, f"{code}\n{done.stderr[-3000:]}"
