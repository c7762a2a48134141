"""Readers of one scene value each: they check its type and range and name its key path on error.

Each raises :class:`~dlo_ros.scene.format.SceneError` whose message starts with the key path it
was given (``grips[1].position[2]: expected a number, got str 'x'``), and checks a list's length
against :data:`~dlo_ros.scene.format.LIMITS` before reading its items.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.profile import Profile
from ..model.rotations import check_quaternion
from .format import LIMITS, QUATERNION_TOLERANCE, SceneError, describe_value, fail, key_text


def read_mapping(value: object, key: str) -> dict:
    """Return ``value`` if it is a mapping with string keys, else SceneError naming ``key``."""
    if not isinstance(value, dict):
        raise fail(key, f"expected a mapping, got {type(value).__name__} {describe_value(value)}")
    for k in value:
        if not isinstance(k, str):
            raise fail(key, f"keys must be strings, got {describe_value(k)}")
    return value


def check_known_keys(d: dict, allowed: tuple[str, ...] | list[str], key: str) -> None:
    """Refuse the first key of ``d`` not in ``allowed``, naming ``key.<that key>``."""
    for k in d:
        if k not in allowed:
            prefix = f"{key}.{key_text(k)}" if key else key_text(k)
            raise fail(prefix, f"unknown key (allowed: {', '.join(allowed)})")


def read_list(value: object, key: str, limit: str | None = None) -> list:
    """Return ``value`` as a list; ``limit`` names the :data:`LIMITS` entry bounding its length.

    The length is checked before any item is looked at.
    """
    if not isinstance(value, (list, tuple)):
        raise fail(key, f"expected a list, got {type(value).__name__} {describe_value(value)}")
    if limit is not None and len(value) > LIMITS[limit]:
        raise fail(key, f"{len(value)} items, at most {LIMITS[limit]} are allowed")
    return list(value)


def read_number(value: object, key: str) -> float:
    """Return ``value`` as a finite float; booleans, strings and huge integers are refused."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise fail(key, f"expected a number, got {type(value).__name__} {describe_value(value)}")
    try:
        v = float(value)
    except OverflowError:  # an int beyond 1.8e308
        raise fail(key, f"out of range: an integer {describe_value(value)}") from None
    if not math.isfinite(v):
        raise fail(key, f"must be finite, got {v}")
    return v


def read_vector(value: object, n: int, key: str) -> np.ndarray:
    """Return a list of exactly ``n`` finite numbers as a float array (items named ``key[i]``)."""
    items = read_list(value, key)
    if len(items) != n:
        raise fail(key, f"expected {n} numbers, got {len(items)}")
    return np.array([read_number(v, f"{key}[{i}]") for i, v in enumerate(items)], dtype=float)


def read_string(
    value: object, key: str, allow_empty: bool = True, limit: str = "name_chars"
) -> str:
    """Return a string of at most ``LIMITS[limit]`` characters.

    Control characters are refused unless it is the description (``limit="description_chars"``).
    """
    if not isinstance(value, str):
        raise fail(key, f"expected a string, got {type(value).__name__} {describe_value(value)}")
    if len(value) > LIMITS[limit]:
        raise fail(key, f"{len(value)} characters, at most {LIMITS[limit]} are allowed")
    if limit != "description_chars" and not value.isprintable():
        raise fail(
            key, f"must be printable text without control characters, got {describe_value(value)}"
        )
    if not allow_empty and not value.strip():
        raise fail(key, "must not be empty")
    return value


def read_arc_length(value: object, key: str, length: float) -> float:
    """Return an arc length s [m] in [0, ``length``]."""
    s = read_number(value, key)
    if not 0.0 <= s <= length:
        raise fail(key, f"must lie in [0, string.length = {length:g}], got {s:g}")
    return s


def read_quaternion(value: object, key: str) -> np.ndarray:
    """Return a unit quaternion (x, y, z, w); its norm must be 1 within QUATERNION_TOLERANCE."""
    q = read_vector(value, 4, key)
    try:
        return check_quaternion(q, key, QUATERNION_TOLERANCE)
    except ValueError as exc:
        raise SceneError(str(exc), key=key) from None


def read_profile(value: object, key: str, length: float, minimum: float, strict: bool) -> Profile:
    """Return a property along the string: a number, or ``{table: [[s, value], ...]}``.

    A table is piecewise linear in s, its s strictly increasing in [0, ``length``]; every value is
    >= ``minimum`` (> when ``strict``).
    """
    bound = "> 0" if strict else ">= 0"

    def check(v: float, where: str) -> None:
        if v < minimum or (strict and v <= minimum):
            raise fail(where, f"must be {bound}, got {v:g}")

    if isinstance(value, dict):
        check_known_keys(value, ("table",), key)
        if "table" not in value:
            raise fail(key, "a profile mapping needs 'table: [[s, value], ...]'")
        rows = read_list(value["table"], f"{key}.table", "profile_rows")
        if not rows:
            raise fail(f"{key}.table", "needs at least one [s, value] row")
        table: list[tuple[float, float]] = []
        for i, row in enumerate(rows):
            where = f"{key}.table[{i}]"
            pair = read_vector(row, 2, where)
            if not 0.0 <= pair[0] <= length:
                raise fail(
                    f"{where}[0]",
                    f"s must lie in [0, string.length = {length:g}], got {pair[0]:g}",
                )
            if table and pair[0] <= table[-1][0]:
                raise fail(
                    f"{where}[0]",
                    f"s values must be strictly increasing, got {pair[0]:g} after "
                    f"{table[-1][0]:g}",
                )
            check(float(pair[1]), f"{where}[1]")
            table.append((float(pair[0]), float(pair[1])))
        return Profile.table(table)
    v = read_number(value, key)
    check(v, key)
    return Profile.constant(v)
