"""Opening a recording in the rerun viewer, or rendering it headlessly to a PNG."""

from __future__ import annotations

import os
import shutil
import socket
import sys
import time
from pathlib import Path

from .paths import TIMELINE_UPDATE
from .recorder import has_display

__all__ = ["has_display", "no_display_message", "rerun_command", "screenshot"]


def rerun_command() -> list[str]:
    """Return the command that starts the rerun viewer.

    The rerun viewer executable: $DLO_RERUN_EXE, the venv's ``rerun``, ``rerun`` on PATH, or
    ``python -m rerun``.
    """
    if os.environ.get("DLO_RERUN_EXE"):
        return [os.environ["DLO_RERUN_EXE"]]
    beside = Path(sys.executable).parent / "rerun"
    if beside.exists():
        return [str(beside)]
    found = shutil.which("rerun")
    return [found] if found else [sys.executable, "-m", "rerun"]


def no_display_message(path: Path) -> str:
    return "\n".join(
        [
            f"dlo replay: no display here ($DISPLAY and $WAYLAND_DISPLAY are unset), so the rerun "
            f"viewer cannot "
            f"open a window for {path}.",
            "Instead:",
            f"  * on a machine with a display: `dlo replay {path}` or `rerun {path}` (rerun-sdk "
            f"0.41: "
            "`pip install rerun-sdk==0.41.0`)",
            f"  * in a browser, no display needed: `dlo replay {path} --web` (serves "
            f"http://localhost:9090;"
            " forward the ports 9090 and 9876 over ssh: `ssh -L 9090:localhost:9090 -L "
            "9876:localhost:9876 HOST`)",
            f"  * as an image: `dlo replay {path} --screenshot out.png` (headless; needs a Vulkan "
            f"driver, "
            "e.g. Debian's mesa-vulkan-drivers)",
            f"  * as a regression check: `dlo replay {path} --resolve`",
        ]
    )


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def screenshot(
    path: str | Path, png: str | Path, *, update: int | None = None, wait: float = 6.0
) -> Path:
    """Render a recording with a headless rerun viewer into ``png``.

    Render a recording with a headless rerun viewer (its default blueprint, 1920×1080) into
    ``png``.

    ``update``: the update to show (default: the last).  Raises RuntimeError with the viewer's
    reason when it cannot start (e.g. no Vulkan adapter: install a software one, Debian's
    mesa-vulkan-drivers).
    """
    from rerun.experimental import ViewerClient  # optional: rerun-sdk

    path, png = Path(path).resolve(), Path(png).resolve()
    viewer = ViewerClient.spawn(headless=True, port=_free_port(), hide_welcome_screen=True)
    try:
        viewer.open(str(path))
        deadline = time.monotonic() + 60
        while viewer.get_state().loading and time.monotonic() < deadline:
            time.sleep(0.2)
        if update is not None:
            viewer.set_time(TIMELINE_UPDATE, sequence=int(update), play_state="paused")
        time.sleep(wait)  # let the software renderer paint and the start-up notifications fade
        data = viewer.take_screenshot()
        if not data:
            raise RuntimeError("the viewer returned an empty screenshot")
        png.parent.mkdir(parents=True, exist_ok=True)
        png.write_bytes(data)
    finally:
        try:
            viewer.quit()
        except Exception:  # noqa: BLE001 - best effort
            pass
    return png
