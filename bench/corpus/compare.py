"""Compare two behaviour corpora (bench/corpus/collect.py): one line per case, then a summary.

A float differs when |a − b| > tol · max(1, |a|) (absolute below magnitude 1, relative above: a
grip force of 30 N cannot agree better than its last bits); NaN matches NaN only.  A case differs
when any float of it does, or any discrete field (status, stability verdict, warm start, iteration
and continuation counts, IPOPT status, the model summary's non-numeric entries, the array shapes)
does; wall-clock durations quoted in auto's change reasons (its stall reports) are ignored
(``untimed``).  Messages that differ are counted but do not fail the comparison.

    bash scripts/dlo-env run python bench/corpus/compare.py A.npz B.npz [--tol 1e-12]

Exit code 0: every case matches; 1: a case differs or is missing from either file; 2: bad input.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from dataclasses import dataclass, field

import numpy as np

#: the float arrays of a case and the column they are reported in
FLOATS = {
    "points": "points",
    "wrench": "wrench",
    "min_eigenvalue": "eigen",
    "orientations": "other",
    "contact_forces": "other",
    "self_contacts": "other",
    "energy_total": "other",
    "equilibrium_residual_m": "other",
    "constraint_violation": "other",
    "min_self_distance": "other",
}
#: the fields compared exactly
DISCRETE = (
    "status",
    "stable",
    "warm_started",
    "iterations",
    "continuation_steps",
    "ipopt_status",
    "grip_names",
)

#: the stall report auto appends to a change's reason when switching took over 0.05 s / 0.2 s
#: ("[waited 0.00 s for the worker's build, 0.22 s to set up the pooled model]", AutoShapeSolver):
#: whether it is there at all is wall-clock timing, not behaviour
STALL = re.compile(r" ?\[waited [^\]]*\]")
#: any other wall-clock duration quoted in a string, compared as "<t> s"
DURATION = re.compile(r"\d+(?:\.\d+)?(?:e[-+]?\d+)? ?(s|ms)\b")


def untimed(value: object) -> object:
    """Return ``value`` with auto's stall reports dropped and other durations made placeholders."""
    if isinstance(value, str):
        return DURATION.sub(r"<t> \1", STALL.sub("", value))
    if isinstance(value, list):
        return [untimed(v) for v in value]
    return value


@dataclass
class CaseDiff:
    """How one case differs: the largest scaled difference per column and the exact mismatches."""

    name: str
    largest: dict[str, float] = field(default_factory=dict)
    mismatches: list[str] = field(default_factory=list)
    messages: int = 0

    def worst(self) -> float:
        """Return the largest scaled float difference of the case (0 when none)."""
        return max(self.largest.values(), default=0.0)


def float_diff(a: np.ndarray, b: np.ndarray) -> float:
    """Return max |a − b| / max(1, |a|) over the entries (inf where one side only is NaN)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape:
        return float("inf")
    if a.size == 0:
        return 0.0
    nan_a, nan_b = np.isnan(a), np.isnan(b)
    if np.any(nan_a != nan_b):
        return float("inf")
    both = ~nan_a
    scale = np.maximum(1.0, np.abs(a[both]))
    with np.errstate(invalid="ignore"):  # inf − inf where both are infinite and equal
        delta = np.where(a[both] == b[both], 0.0, np.abs(a[both] - b[both]) / scale)
    return float(np.max(delta, initial=0.0))


def model_diff(a: str, b: str) -> tuple[float, bool]:
    """Return the summaries' largest numeric difference and whether their other entries agree."""
    da, db = json.loads(a), json.loads(b)
    if set(da) != set(db):
        return 0.0, False
    largest, same = 0.0, True
    for key in da:
        x, y = da[key], db[key]
        numbers = (int, float)
        if isinstance(x, numbers) and isinstance(y, numbers) and not isinstance(x, bool):
            largest = max(largest, float_diff(np.array(x), np.array(y)))
        elif isinstance(x, list) and all(isinstance(v, numbers) for v in x + y) and x and y:
            largest = max(largest, float_diff(np.array(x), np.array(y)))
        elif untimed(x) != untimed(y):
            same = False
    return largest, same


def compare_case(name: str, a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> CaseDiff:
    """Compare one case of two corpora (``a``, ``b``: its arrays by field)."""
    out = CaseDiff(name)
    for key, column in FLOATS.items():
        out.largest[column] = max(out.largest.get(column, 0.0), float_diff(a[key], b[key]))
    for key in DISCRETE:
        x, y = a[key], b[key]
        same = x.shape == y.shape and bool(
            np.all((x == y) | (np.isnan(x) & np.isnan(y)) if x.dtype.kind == "f" else x == y)
        )
        if not same:
            out.mismatches.append(key)
    if a["model"].shape != b["model"].shape:
        out.mismatches.append("model")
    else:
        for x, y in zip(a["model"], b["model"]):
            largest, same = model_diff(str(x), str(y))
            out.largest["other"] = max(out.largest["other"], largest)
            if not same and "model" not in out.mismatches:
                out.mismatches.append("model")
    if a["message"].shape == b["message"].shape:
        out.messages = sum(
            untimed(str(x)) != untimed(str(y)) for x, y in zip(a["message"], b["message"])
        )
    return out


def load(path: str) -> tuple[dict, dict[str, dict[str, np.ndarray]]]:
    """Read a corpus: its metadata and, per case, its arrays by field."""
    cases: dict[str, dict[str, np.ndarray]] = {}
    with np.load(path, allow_pickle=False) as data:
        meta = json.loads(str(data["__meta__"]))
        for key in data.files:
            if key == "__meta__":
                continue
            case, name = key.split("::", 1)
            cases.setdefault(case, {})[name] = data[key]
    return meta, cases


def main(argv: list[str] | None = None) -> int:
    """Print the comparison of two corpora; 0 when they agree to ``--tol``, else 1."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a")
    ap.add_argument("b")
    ap.add_argument("--tol", type=float, default=1e-12)
    args = ap.parse_args(argv)
    try:
        meta_a, a = load(args.a)
        meta_b, b = load(args.b)
    except (OSError, ValueError, KeyError) as exc:
        print(f"compare: error: {exc}", file=sys.stderr)
        return 2
    print(f"A: {args.a} (git {meta_a['git']})\nB: {args.b} (git {meta_b['git']})")
    header = f"{'case':42s} {'results':>7s} {'points':>9s} {'wrench':>9s} {'eigen':>9s}"
    print(f"{header} {'other':>9s}  status  mismatches")
    failed, messages = [], 0
    for name in sorted(set(a) | set(b)):
        if name not in a or name not in b:
            print(f"{name:42s} only in {'A' if name in a else 'B'}")
            failed.append(name)
            continue
        d = compare_case(name, a[name], b[name])
        messages += d.messages
        status_same = "status" not in d.mismatches
        cols = " ".join(f"{d.largest[c]:9.1e}" for c in ("points", "wrench", "eigen", "other"))
        others = ",".join(m for m in d.mismatches if m != "status") or "-"
        note = f" ({d.messages} messages differ)" if d.messages else ""
        results = len(a[name]["status"])
        status = "same" if status_same else "DIFF"
        print(f"{name:42s} {results:7d} {cols}  {status:6s}  {others}{note}")
        if d.mismatches or d.worst() > args.tol:
            failed.append(name)
    print(
        f"\n{len(set(a) | set(b))} cases, {len(failed)} differ beyond tol {args.tol:g} "
        f"(scaled: |Δ| / max(1, |a|)) or in a discrete field; {messages} messages differ"
    )
    for name in failed:
        print(f"  differs: {name}")
    skipped = {**meta_a.get("skipped", {}), **meta_b.get("skipped", {})}
    for name, why in skipped.items():
        print(f"  skipped: {name}: {why}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
