"""The compiled Newton drivers' C (dlo_ros/solver/native/) compiles without a warning under
``-Wall -Wextra -Werror``, with the flags and ``-D`` settings the library build uses, and only with
those settings: the C holds no second copy of a number the Python paths use (#36)."""
from __future__ import annotations

import subprocess
from importlib import resources
from pathlib import Path

import pytest

from dlo_ros.solver.native import build as native_build
from dlo_ros.solver.build.compiled import compiler

pytestmark = pytest.mark.skipif(compiler() is None, reason="no C compiler (gcc, cc, clang or $CC)")

#: stand-ins for the generated functions' names (the library's -D names; here nothing is linked)
NAMES = ("-DDLO_SYSTEM=dlo_system", "-DDLO_SYSTEM_WORK=dlo_system_work",
         "-DDLO_RESIDUAL=dlo_residual", "-DDLO_RESIDUAL_WORK=dlo_residual_work")
WARNINGS = ("-Wall", "-Wextra", "-Werror")


@pytest.fixture(scope="module")
def native_dir(tmp_path_factory) -> Path:
    """The shipped C files and headers, as the package holds them (importlib.resources)."""
    out = tmp_path_factory.mktemp("native")
    for entry in resources.files("dlo_ros.solver").joinpath("native").iterdir():
        if entry.name.endswith((".c", ".h")):
            (out / entry.name).write_text(entry.read_text(encoding="utf-8"), encoding="utf-8")
    return out


def compile_c(native_dir: Path, name: str, *flags: str) -> subprocess.CompletedProcess:
    cmd = [compiler(), "-c", "-fPIC", *flags, "-o", str(native_dir / f"{name}.o"),
           str(native_dir / name)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


def test_the_drivers_are_shipped():
    assert native_build.c_files() == ["newton_active.c", "newton_free.c", "saddle_escape.c"]


@pytest.mark.parametrize("name", native_build.c_files())
@pytest.mark.parametrize("optimise", ["-O0", "build"])
def test_every_c_file_compiles_without_a_warning(native_dir, name, optimise):
    """At the build's flags (-O3: its flow analysis finds maybe-uninitialised values), and -O0."""
    flags = native_build.settings_flags()
    if optimise != "build":
        flags = (optimise, *flags[1:])  # compiled.FLAGS is the optimisation level alone
    done = compile_c(native_dir, name, *WARNINGS, *flags, *NAMES)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize("name", native_build.c_files())
def test_a_driver_without_the_shared_settings_does_not_compile(native_dir, name):
    """Without the -D settings the build stops at dlo_native.h's #error, which names where they
    come from."""
    done = compile_c(native_dir, name, *NAMES)
    assert done.returncode != 0 and "native/settings.py" in done.stderr


def test_the_library_source_is_the_files_with_their_headers(native_dir):
    """What the library build appends to the generated code: each driver with its local includes
    replaced by the headers' text, each once, so it compiles with no include path."""
    for name in native_build.c_files():
        text = native_build.driver_source(name)
        assert '#include "' not in text
        assert text.count("#define DLO_NATIVE_H") == 1 and text.count("#define DLO_COMMON_H") == 1
        isolated = native_dir / "isolated"  # no header beside it
        isolated.mkdir(exist_ok=True)
        (isolated / name).write_text(text, encoding="utf-8")
        done = compile_c(isolated, name, *WARNINGS, *native_build.settings_flags(), *NAMES)
        assert done.returncode == 0, done.stderr
