"""Memory of the managed node through configure -> activate -> stream -> deactivate -> cleanup cycles.

Starts ``dlo node --managed`` (its own ROS domain, ``query_workers:=0``: the node's own resident
memory only, interpreted derivatives) with each solver.model, drives its lifecycle over DDS with
``LifecycleClient`` and reads the node process's RSS: unconfigured, after configure, after 2 s of
streaming a moved target, after cleanup.  The first configure also loads what a process loads once
(IPOPT's and CasADi's plugins, the basis memos): the cycles after it show what cleanup returns.
Writes bench/results/managed_memory.md.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # run as a script: make `bench` importable
from bench.common import machine, write_report  # noqa: E402
from dlo_ros.node.client import DloClient, NodeProcess, allocate_domain_id  # noqa: E402
from dlo_ros.node.client.lifecycle import LifecycleClient  # noqa: E402

Q = (0.0, 0.0, 0.0, 1.0)
TARGETS = [((0.0, 0.0, 0.4), Q), ((0.45, 0.1, 0.3), Q)]


def cycles(model: str, n: int) -> tuple[float, list[tuple[float, float, float]]]:
    """RSS [MB] unconfigured, then (configured, streamed, cleaned up) per cycle."""
    with allocate_domain_id() as lease:
        proc = NodeProcess(["--managed", "--ros-args", "-p", "compile:=off", "-p", f"solver.model:={model}",
                            "-p", "query_workers:=0"], lease.domain_id)
        try:
            with DloClient(lease.domain_id) as client:
                lc = LifecycleClient(client)
                assert lc.state(60.0) == "unconfigured"
                base = proc.rss_bytes() / 1e6
                rows = []
                for _ in range(n):
                    assert lc.change("configure", 120.0), proc.output()
                    configured = proc.rss_bytes() / 1e6
                    assert lc.change("activate")
                    client.publish_targets(TARGETS)
                    time.sleep(2.0)
                    streamed = proc.rss_bytes() / 1e6
                    assert lc.change("deactivate") and lc.change("cleanup")
                    time.sleep(0.5)
                    rows.append((configured, streamed, proc.rss_bytes() / 1e6))
                assert lc.change("shutdown")
            proc.wait(15.0)
        finally:
            proc.stop()
            proc.close()
    return base, rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cycles", type=int, default=5)
    ap.add_argument("--out", default="bench/results/managed_memory.md")
    args = ap.parse_args(argv)
    m = machine()
    lines = ["# The managed node's memory over lifecycle cycles", "",
             f"Machine: {m.get('cpu')}, {m.get('cpus')} cores, Python {m.get('python')}, load average "
             f"{m.get('load_average')}; git {m.get('git')}.", "",
             "RSS [MB] of the node process (`default_cable`, interpreted, `query_workers:=0`): unconfigured, "
             "then per cycle after configure, after 2 s of streaming a moved target, after cleanup. "
             "Returned: streamed - after cleanup.", "",
             "| solver.model | unconfigured | cycle | configured | streamed | after cleanup | returned |",
             "|---|---|---|---|---|---|---|"]
    for model in ("full", "auto"):
        base, rows = cycles(model, args.cycles)
        for i, (configured, streamed, cleaned) in enumerate(rows, start=1):
            lines.append(f"| {model} | {base:.0f} | {i} | {configured:.0f} | {streamed:.0f} | {cleaned:.0f} | "
                         f"{streamed - cleaned:.0f} |")
    write_report(lines, args.out, "bench/perf/managed_memory.py", sys.argv[1:] if argv is None else argv)


if __name__ == "__main__":
    main()
