"""Node soak: targets at 100 Hz on a gentle 3D path for minutes, with live parameter changes and
concurrent shape queries, over real DDS; RSS, latency, failures, stamp/shape agreement, model.

    bash scripts/dlo-env run python bench/perf/soak.py [--seconds 600] [--rate 100] [--param-every 60]
        [--query-clients 2] [--query-rate 5] [--compile background] [--out bench/results/soak.md]

The node runs the default scene with ``solver.model: auto`` in its own process and ROS domain, with
``--compile`` (default ``background``, the node's own default: interpreted derivatives until gcc has
built the scene's, from the cache when an earlier run built them; ``off``: interpreted throughout); this
process publishes the right grip's targets along a closed 3D path (±5 cm, ±0.2 rad of yaw, ±0.6 rad of
twist, one loop per 20 s) and receives the centrelines. Every ``--param-every`` s it changes
``string.bend_stiffness`` (0.02 ↔ 0.025 N·m²) through the parameter service; ``--query-clients`` clients
(each its own DDS participant) call ``~/query_shape`` at ``--query-rate`` Hz each with the right grip 2–4
cm from the current target. Every 10 s it samples the node's RSS, its query workers' RSS and its
diagnostics. Reported first, the issue #35 table: stream failures (must be 0), valid queries answered
with an empty plan (must be 0), the node's and the workers' RSS change after the first minute (flat
within 5 %), latency p50/p99/max; then RSS over time, latency target → centreline p50/p99/max, centrelines per second,
failures and unverified shapes, query latency and answers, and every centreline whose stamp and shape
disagree (its right end not at the target published with that stamp by more than 1e-6 m).
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the repository
sys.path.insert(0, str(ROOT))  # run as a script: make `bench` importable

from bench.common import machine  # noqa: E402

from dlo_ros.node.client import DloClient, running_node  # noqa: E402

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


class Queries(threading.Thread):
    """One query client: ~/query_shape at ``rate`` Hz around the stream's current target, until stopped."""

    def __init__(self, domain_id: int, index: int, rate: float, now):
        super().__init__(name=f"soak-query-{index}", daemon=True)
        self.domain_id, self.index, self.rate, self.now = domain_id, index, rate, now
        self.latency_ms: list[float] = []
        self.answered = self.empty = self.errors = 0
        self.stop = threading.Event()

    def run(self) -> None:
        rng = np.random.default_rng(self.index)
        with DloClient(self.domain_id, client_name=f"soak_query_{self.index}") as cl:
            while not self.stop.wait(1.0 / self.rate):
                left, (pos, q) = target(self.now())
                offset = rng.normal(size=3)
                goal = (tuple(np.asarray(pos) + 0.02 * (1 + rng.random()) * offset / np.linalg.norm(offset)), q)
                t0 = time.monotonic()
                try:
                    points, _ = cl.query(left, goal, timeout=30.0)
                except Exception:  # noqa: BLE001 - counted: a timeout or a service error
                    self.errors += 1
                    continue
                self.latency_ms.append((time.monotonic() - t0) * 1e3)
                if len(points):
                    self.answered += 1
                else:
                    self.empty += 1


def worker_rss_mb(pid: int) -> list[float]:
    """RSS [MB] of each worker process (query and fit workers: multiprocessing's spawned children) of the
    node ``pid``, in pid order (Linux /proc; empty elsewhere)."""
    out = []
    for entry in sorted((e for e in os.listdir("/proc") if e.isdigit()), key=int):
        try:
            with open(f"/proc/{entry}/stat") as f:
                stat = f.read()
            if int(stat[stat.rindex(")") + 2:].split()[1]) != pid:
                continue
            with open(f"/proc/{entry}/cmdline") as f:
                if "spawn_main" not in f.read():
                    continue
            with open(f"/proc/{entry}/status") as f:
                rss = next(int(line.split()[1]) for line in f if line.startswith("VmRSS:"))
            out.append(rss / 1024)
        except (OSError, ValueError, IndexError, StopIteration):
            continue
    return out


def change_after_first_minute(t: np.ndarray, mb: np.ndarray) -> str:
    """'a → b MB (+x %)': from the first sample at t >= 60 s to the last one."""
    after = mb[t >= 60.0]
    if len(after) < 2:
        return "n/a (run shorter than a minute)"
    return f"{after[0]:.0f} → {after[-1]:.0f} MB ({(after[-1] - after[0]) / after[0] * 100:+.1f} %)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=600.0)
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--param-every", type=float, default=60.0, help="seconds between parameter changes (0: none)")
    ap.add_argument("--query-clients", type=int, default=2)
    ap.add_argument("--query-rate", type=float, default=5.0, help="queries per second per client")
    ap.add_argument("--compile", default="background", choices=("background", "blocking", "off"),
                    help="the node's compile parameter (default: its own default)")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "soak.md"))
    args = ap.parse_args()
    samples, sent, changes = [], {}, []
    with running_node("--ros-args", "-p", f"compile:={args.compile}", startup_timeout=300.0,
                      client_name="soak") as (proc, cl):
        c0, start = cl.path_count, time.monotonic()
        clock = lambda: time.monotonic() - start  # noqa: E731
        queries = [Queries(proc.domain_id, i, args.query_rate, clock) for i in range(args.query_clients)]
        for q in queries:
            q.start()
        k, next_sample = 0, 0.0
        next_change = args.param_every if args.param_every > 0 else math.inf
        while (now := clock()) < args.seconds:
            poses = target(now)
            sent[cl.publish_targets(poses)] = np.asarray(poses[1][0])
            k += 1
            if now >= next_change:
                bend = 0.025 if len(changes) % 2 == 0 else 0.02
                t0 = time.monotonic()
                ok, reason = cl.set_parameters({"string.bend_stiffness": bend})[0]
                changes.append((now, bend, ok, reason, (time.monotonic() - t0) * 1e3))
                next_change += args.param_every
            if now >= next_sample:
                v = cl.diagnostic_values()
                samples.append((now, proc.rss_bytes() / 2**20, cl.path_count - c0, v.get("model.order", ""),
                                v.get("model.planar", ""), v.get("model.estimated_error_m", ""),
                                v.get("failures", ""), v.get("unverified updates", ""),
                                worker_rss_mb(proc.pid)))
                next_sample += 10.0
            time.sleep(max(0.0, start + k / args.rate - time.monotonic()))
        elapsed = clock()
        for q in queries:
            q.stop.set()
        for q in queries:
            q.join(60.0)
        time.sleep(1.0)
        events = [e for e in list(cl.paths)[-(cl.path_count - c0):] if e.stamp_ns in sent]
        final = cl.diagnostic_values()
    miss = np.array([np.linalg.norm(e.points[-1] - sent[e.stamp_ns]) for e in events])
    mismatch = [(e, m) for e, m in zip(events, miss) if m > 1e-6]
    lat = np.array([(e.received_ns - e.stamp_ns) / 1e6 for e in events])
    t_event = np.array([(e.stamp_ns - events[0].stamp_ns) / 1e9 for e in events])
    worst = np.argsort(lat)[::-1][:5]
    rss = np.array([s[1] for s in samples])
    after = rss[[i for i, s in enumerate(samples) if s[0] >= 60.0]]
    qlat = np.concatenate([q.latency_ms for q in queries]) if queries else np.array([])
    info = machine()
    t_s = np.array([s[0] for s in samples])
    n_workers = max((len(s[8]) for s in samples), default=0)
    workers = [np.array([s[8][i] if i < len(s[8]) else np.nan for s in samples]) for i in range(n_workers)]
    lines = ["# Node soak", "",
             f"Machine: {info.get('cpu', '?')}, {info.get('cpus')} cores, Python {info.get('python')}; git {info.get('git', '?')}.",
             f"Command: `bash scripts/dlo-env run python bench/perf/soak.py --seconds {args.seconds:g} --rate {args.rate:g} "
             f"--param-every {args.param_every:g} --query-clients {args.query_clients} "
             f"--query-rate {args.query_rate:g} --compile {args.compile}`", "",
             "| issue #35 | value | target |", "|---|---|---|",
             f"| stream failures | {final.get('failures')} | 0 |",
             f"| valid queries answered with an empty plan | "
             f"{sum(q.empty for q in queries) if queries else 'n/a'} of "
             f"{sum(q.answered + q.empty + q.errors for q in queries)} "
             f"({sum(q.errors for q in queries)} client errors/timeouts) | 0 |",
             f"| node RSS after minute 1 | {change_after_first_minute(t_s, rss)} | within 5 % |"]
    lines += [f"| query/fit worker {i + 1} RSS after minute 1 | {change_after_first_minute(t_s, w)} | within 5 % |"
              for i, w in enumerate(workers)]
    lines += [f"| latency target → centreline p50 / p99 / max | {np.percentile(lat, 50):.1f} / "
              f"{np.percentile(lat, 99):.1f} / {lat.max():.0f} ms | |",
              f"| query latency p50 / p99 / max | "
              + (f"{np.percentile(qlat, 50):.0f} / {np.percentile(qlat, 99):.0f} / {qlat.max():.0f} ms"
                 if len(qlat) else "n/a") + " | |", "",
             f"{k} targets in {elapsed:.0f} s ({k / elapsed:.0f}/s), {len(events)} centrelines ({len(events) / elapsed:.1f}/s); "
             f"latency target → centreline p50 {np.percentile(lat, 50):.1f} ms, p99 {np.percentile(lat, 99):.1f} ms, "
             f"max {lat.max():.0f} ms; failures {final.get('failures')}, unverified shapes {final.get('unverified updates')}, "
             f"rejected {final.get('rejected inputs')}.  Largest latencies: "
             + ", ".join(f"{lat[i]:.0f} ms at t = {t_event[i]:.1f} s" for i in worst) + ".",
             f"Centrelines whose right end is not at the target sent with their stamp (> 1e-6 m): {len(mismatch)}"
             + (": " + ", ".join(f"{m * 1e3:.3g} mm at t = {(e.stamp_ns - events[0].stamp_ns) / 1e9:.1f} s"
                                 for e, m in mismatch[:10]) if mismatch else "") + ".",
             f"Model at the end: planar {final.get('model.planar')}, order {final.get('model.order')}, "
             f"rotation {final.get('model.rotation', '?')}, estimated error {final.get('model.estimated_error_m')} m "
             f"(tolerance met: {final.get('model.tolerance_met')}), {final.get('model.changes')} model changes.",
             f"RSS: {rss[0]:.0f} MB at start, {rss.max():.0f} MB peak; after the first minute "
             f"{after.min():.0f}–{after.max():.0f} MB ({(after.max() - after.min()) / after.mean() * 100:.1f} % spread)."
             if len(after) else f"RSS: {rss[0]:.0f} MB at start, {rss.max():.0f} MB peak (run shorter than a minute)."]
    if queries:
        n_q = sum(q.answered + q.empty + q.errors for q in queries)
        lines.append(f"Queries: {n_q} from {len(queries)} clients; {sum(q.answered for q in queries)} answered with a "
                     f"shape, {sum(q.empty for q in queries)} refused (no stable equilibrium), "
                     f"{sum(q.errors for q in queries)} errors or timeouts; latency p50 "
                     f"{np.percentile(qlat, 50) if len(qlat) else float('nan'):.0f} ms, p99 "
                     f"{np.percentile(qlat, 99) if len(qlat) else float('nan'):.0f} ms, max "
                     f"{qlat.max() if len(qlat) else float('nan'):.0f} ms.")
    if changes:
        lines.append("Parameter changes (string.bend_stiffness): " + "; ".join(
            f"t = {t:.0f} s → {b:g} ({'accepted' if ok else 'refused: ' + reason}, {ms:.0f} ms)"
            for t, b, ok, reason, ms in changes) + ".")
    lines += ["", "| t s | RSS MB | workers' RSS MB | centrelines | order | planar | estimated error m | failures "
              "| unverified |", "|---|---|---|---|---|---|---|---|---|"]
    lines += [f"| {s[0]:.0f} | {s[1]:.0f} | {', '.join(f'{m:.0f}' for m in s[8]) or '-'} | {s[2]} | {s[3]} | "
              f"{s[4]} | {s[5]} | {s[6]} | {s[7]} |" for s in samples]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
