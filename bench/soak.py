"""Node soak: targets at 100 Hz on a gentle 3D path for minutes, over real DDS; RSS, latency, model.

    bash scripts/dlo-env run python bench/soak.py [--seconds 300] [--rate 100] [--out bench/results/soak.md]

The node runs the default scene with ``solver.model: auto`` (interpreted derivatives) in its own process
and ROS domain; this process publishes the right grip's targets along a closed 3D path (±5 cm,
±0.2 rad of yaw, ±0.6 rad of twist, one loop per 20 s) and receives the centrelines.  Every 10 s it
samples the node's RSS and its diagnostics (model, order, estimated error, failures).  Reported: RSS
over time, its change after the first minute, latency target → centreline p50/p99/max, centrelines per
second, failures and unverified shapes, and the model the node ends on.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from common import machine  # noqa: E402

from dlo_ros.node.client import running_node  # noqa: E402

Q0 = (0.0, 0.0, 0.0, 1.0)
LEFT = ((0.0, 0.0, 0.4), Q0)


def target(t: float):
    a = 2 * math.pi * t / 20.0
    pos = (0.55 + 0.05 * math.cos(a), 0.05 * math.sin(a), 0.42 + 0.03 * math.sin(2 * a))
    yaw, twist = 0.2 * math.sin(a), 0.6 * math.sin(a)
    # q = yaw about z, then twist about the (turned) x axis
    qz = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    qx = (math.sin(twist / 2), 0.0, 0.0, math.cos(twist / 2))
    x1, y1, z1, w1 = qz
    x2, y2, z2, w2 = qx
    q = (w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2, w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
         w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2, w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2)
    return [LEFT, (pos, q)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=300.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "soak.md"))
    args = ap.parse_args()
    samples, stamps = [], set()
    with running_node("--ros-args", "-p", "compile:=off", startup_timeout=300.0, client_name="soak") as (proc, cl):
        c0, start = cl.path_count, time.monotonic()
        k, next_sample = 0, 0.0
        while (now := time.monotonic() - start) < args.seconds:
            stamps.add(cl.publish_targets(target(now)))
            k += 1
            if now >= next_sample:
                v = cl.diagnostic_values()
                samples.append((now, proc.rss_bytes() / 2**20, cl.path_count - c0, v.get("model.order", ""),
                                v.get("model.planar", ""), v.get("model.estimated_error_m", ""),
                                v.get("failures", ""), v.get("unverified updates", "")))
                next_sample += 10.0
            time.sleep(max(0.0, start + k / args.rate - time.monotonic()))
        elapsed = time.monotonic() - start
        time.sleep(1.0)
        events = [e for e in list(cl.paths)[-(cl.path_count - c0):] if e.stamp_ns in stamps]
        final = cl.diagnostic_values()
    lat = np.array([(e.received_ns - e.stamp_ns) / 1e6 for e in events])
    t_event = np.array([(e.stamp_ns - events[0].stamp_ns) / 1e9 for e in events])
    worst = np.argsort(lat)[::-1][:5]
    rss = np.array([s[1] for s in samples])
    after = rss[[i for i, s in enumerate(samples) if s[0] >= 60.0]]
    info = machine()
    lines = ["# Node soak", "",
             f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores, Python {info.get('python')}; git {info.get('git', '?')}.",
             f"Command: `bash scripts/dlo-env run python bench/soak.py --seconds {args.seconds:g} --rate {args.rate:g}`", "",
             f"{k} targets in {elapsed:.0f} s ({k / elapsed:.0f}/s), {len(events)} centrelines ({len(events) / elapsed:.1f}/s); "
             f"latency target → centreline p50 {np.percentile(lat, 50):.1f} ms, p99 {np.percentile(lat, 99):.1f} ms, "
             f"max {lat.max():.0f} ms; failures {final.get('failures')}, unverified shapes {final.get('unverified updates')}, "
             f"rejected {final.get('rejected inputs')}.  Largest latencies: "
             + ", ".join(f"{lat[i]:.0f} ms at t = {t_event[i]:.1f} s" for i in worst) + ".",
             f"Model at the end: planar {final.get('model.planar')}, order {final.get('model.order')}, "
             f"rotation {final.get('model.rotation', '?')}, estimated error {final.get('model.estimated_error_m')} m "
             f"(tolerance met: {final.get('model.tolerance_met')}), {final.get('model.changes')} model changes.",
             f"RSS: {rss[0]:.0f} MB at start, {rss.max():.0f} MB peak; after the first minute "
             f"{after.min():.0f}–{after.max():.0f} MB ({(after.max() - after.min()) / after.mean() * 100:.1f} % spread).", "",
             "| t s | RSS MB | centrelines | order | planar | estimated error m | failures | unverified |",
             "|---|---|---|---|---|---|---|---|"]
    lines += [f"| {s[0]:.0f} | {s[1]:.0f} | {s[2]} | {s[3]} | {s[4]} | {s[5]} | {s[6]} | {s[7]} |" for s in samples]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
