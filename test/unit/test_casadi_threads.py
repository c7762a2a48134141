"""A CasADi without thread-safe symbolics is refused in one line (``dlo_ros/casadi_threads.py``).

``model: auto`` builds on a worker thread beside the stream's solves, which CasADi supports only
from 3.8 built with CASADI_WITH_THREADSAFE_SYMBOLICS.  The rule on its own; the installed CasADi
passes it; and a process whose CasADi reports no such flag (faked by a ``sitecustomize`` in a
fresh interpreter) gets, from ``dlo`` and ``dlo_node``, exit code 1 and one line naming the fix,
no traceback.  Both executables also turn on ``faulthandler``: a crash in native code prints
every thread's Python stack.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import casadi
import pytest

from dlo_ros.casadi_threads import FLAG, require_threadsafe_casadi, unsupported

BIN = Path(sys.executable).parent


@pytest.mark.parametrize(
    "version, flags, refused",
    [
        ("3.8.2", f"-O2 -D{FLAG} -DCASADI_WITH_THREAD", None),
        ("3.10.0", f"-D{FLAG}", None),
        ("3.7.0", f"-D{FLAG}", "older than 3.8"),
        ("3.6.7", "-O2", "older than 3.8"),
        ("3.8.2", "-O2 -DCASADI_WITH_THREAD", f"built without {FLAG}"),
        ("develop", f"-D{FLAG}", "not a release number"),
    ],
)
def test_the_rule(version, flags, refused):
    why = unsupported(version, flags)
    if refused is None:
        assert why is None
    else:
        assert why is not None and refused in why


def test_the_installed_casadi_passes():
    assert unsupported(casadi.__version__, casadi.CasadiMeta.compiler_flags()) is None
    require_threadsafe_casadi()


@pytest.fixture()
def without_the_flag(tmp_path) -> dict:
    """The environment of a fresh interpreter whose CasADi reports no thread-safe flag."""
    (tmp_path / "sitecustomize.py").write_text(
        "import casadi\ncasadi.CasadiMeta.compiler_flags = staticmethod(lambda: '-O2')\n"
    )
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tmp_path), env.get("PYTHONPATH")]))
    return env


@pytest.mark.parametrize("command", [["dlo", "solve", "default_cable"], ["dlo_node", "--help"]])
def test_a_refused_casadi_is_one_line_naming_the_fix(without_the_flag, command):
    out = subprocess.run(
        [str(BIN / command[0]), *command[1:]],
        env=without_the_flag,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 1, (out.stdout, out.stderr)
    assert "Traceback" not in out.stderr
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, out.stderr
    assert FLAG in lines[0] and "pip install 'casadi>=3.8'" in lines[0]


def test_the_executables_print_a_crash_in_native_code():
    code = (
        "import faulthandler, sys\n"
        "from dlo_ros.console import dlo\n"
        "sys.argv = ['dlo', '--help']\n"
        "try:\n    dlo()\nexcept SystemExit:\n    pass\n"
        "print('FH', faulthandler.is_enabled())\n"
        "import dlo_ros.node, dlo_ros.node.signals as s\n"
        "faulthandler.disable()\n"
        "s.stop_on_first_signal = lambda: None\n"
        "dlo_ros.node.stop_on_first_signal = lambda: None\n"
        "try:\n    dlo_ros.node.main(['--help'])\nexcept SystemExit:\n    pass\n"
        "print('FH', faulthandler.is_enabled())\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    marks = [line for line in out.stdout.splitlines() if line.startswith("FH ")]
    assert marks == ["FH True", "FH True"], out.stdout
