"""What the tests of the ``dlo`` command ask of a refused input (test_hardening_files, test_fit_files)."""
from __future__ import annotations


def assert_one_line_error(code: int, err: str, words: tuple[str, ...]) -> None:
    """Exit code 2, no traceback, and one line on stderr, ``dlo: error: ...``, holding every word."""
    assert code == 2, (code, err)
    assert "Traceback" not in err, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dlo: error: "), err
    for w in words:
        assert w in err, (w, err)
