"""Text that reaches logs, diagnostics and error messages: one printable line, capped.

Text that reaches logs, diagnostics and error messages: one printable line, capped (no ROS, no
numpy).
"""

from __future__ import annotations

import unicodedata
import warnings

#: Longest text (characters, after escaping) that :func:`safe_text` lets into a log line or a
#: diagnostic value.
TEXT_LIMIT = 200

# Unicode categories escaped by safe_text: control (incl. ESC, CR, LF, TAB), format (bidi
# overrides, zero-width), line/paragraph separators, surrogates, private use, unassigned.
_UNSAFE_CATEGORIES = frozenset(("Cc", "Cf", "Zl", "Zp", "Cs", "Co", "Cn"))


def safe_text(value: object, limit: int = TEXT_LIMIT) -> str:
    r"""Return ``value`` as one printable line of at most ``limit`` characters.

    For logs and diagnostics.  Every character a terminal or a log parser could act on (ANSI escape
    sequences start with ESC, newlines, carriage returns, other control and format characters) is
    written as a Python escape (``\x1b``, ``\n``, ``\u202e``), so user-controlled text (frame ids,
    grip names, messages that quote them, file names) cannot forge log lines or recolour a
    terminal.  Longer text is cut and ends with ``…``; only the first ``limit`` characters of
    ``value`` are ever looked at, so a 10 MB string costs as little as a short one.
    """
    text = value if isinstance(value, str) else str(value)
    out: list[str] = []
    size = 0
    for ch in text[: limit + 1]:
        piece = (
            ch.encode("unicode_escape").decode("ascii")
            if unicodedata.category(ch) in _UNSAFE_CATEGORIES
            else ch
        )
        out.append(piece)
        size += len(piece)
        if size > limit:
            break
    joined = "".join(out)
    if size > limit or len(text) > limit:
        return joined[: max(0, limit - 1)] + "…"
    return joined


def one_line_warnings() -> None:
    """Make dlo_ros's warnings print as their message alone, one line on stderr.

    For the ``dlo`` command and the node (applications, not the library): a warning that dlo_ros
    raises (e.g. ``CacheWarning``, an unsafe compiled-code cache) prints as its message alone, one
    line on stderr, instead of Python's ``file:line: Category: message`` plus a line of source
    code, which reads like a traceback.  Other packages' warnings keep Python's format.
    """
    default = warnings.formatwarning

    # untyped: the signature is warnings.formatwarning's
    def formatwarning(message, category, filename, lineno, line=None):
        if category.__module__.startswith("dlo_ros"):
            return f"{message}\n"
        return default(message, category, filename, lineno, line)

    warnings.formatwarning = formatwarning
