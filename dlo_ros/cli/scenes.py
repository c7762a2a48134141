"""``dlo scenes``: list the shipped scenes with the first line of each one's description."""

from __future__ import annotations

import argparse

from ..paths import available_scenes, scene_path
from .common import EXIT_OK

HELP = "list the shipped scenes"


def add_arguments(p: argparse.ArgumentParser) -> None:
    del p  # no options


def scene_summaries() -> list[tuple[str, str]]:
    """(name, first line of the description) of every shipped scene; unreadable files say why."""
    import yaml  # start-up (cli/__init__)

    from ..scene import SceneLoader  # start-up (cli/__init__)

    out = []
    for name in available_scenes():
        try:
            # SceneLoader is a bounded SafeLoader (scene/bounded_yaml.py)
            data = yaml.load(scene_path(name).read_text(encoding="utf-8"), Loader=SceneLoader)
            desc = data.get("description") if isinstance(data, dict) else None
            first = next(
                (ln.strip() for ln in str(desc or "").splitlines() if ln.strip()),
                "(no description)",
            )
        except (OSError, yaml.YAMLError, UnicodeDecodeError) as exc:
            first = f"(unreadable: {type(exc).__name__})"
        out.append((name, first))
    return out


def run(args: argparse.Namespace) -> int:
    del args
    rows = scene_summaries()
    if not rows:
        print("no shipped scenes found")
        return EXIT_OK
    width = max(len(n) for n, _ in rows)
    for name, first in rows:
        print(f"{name:<{width}}  {first}")
    return EXIT_OK
