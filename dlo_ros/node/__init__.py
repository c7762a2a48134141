"""The dlo ROS 2 node (issue 3): ``python -m dlo_ros.node``, ``ros2 run dlo_ros dlo_node``,
launch/dlo.launch.py.

Modules: ``dlo_node`` (the Node and ``main``), ``engine`` (the single solver worker thread and its
"latest pending targets" slot), ``conversions`` (messages <-> numpy), ``validation`` (target
checks), ``params`` (parameter table and checks), ``health`` (diagnostics content and warning
throttling), ``client`` (node subprocess, domain-id leases and a small client, used by the demo,
the benchmark and the tests), ``demo`` (the dual-arm demo job, ``run_demo_job``), and for
identification (``fit.enabled``) ``cloud`` (PointCloud2 → points), ``fitting`` (what is fitted and
when it is applied) and ``fit_node`` (``~/observed``, ``~/fit``).  Interfaces: msg_docs/node.md.
Only ``dlo_node``, ``fit_node``, ``conversions``, ``client`` and ``demo`` import rclpy or messages
(``cloud.points_to_cloud`` on call); importing this package does not.
"""

from __future__ import annotations


def main(argv: list[str] | None = None, prog: str = "python -m dlo_ros.node") -> int:
    """Run the node (the ``dlo_node`` console script); see dlo_ros.node.run.main.

    SIGINT and SIGTERM stop it with exit code 0 from the first moment (see
    :mod:`dlo_ros.node.signals`).
    """
    from .signals import ignore_signals_at_exit, stop_on_first_signal

    stop_on_first_signal()
    try:
        # imported here: the signal handling above must be in place before rclpy and CasADi load
        from .run import main as _main

        return _main(argv, prog=prog)
    except KeyboardInterrupt:  # Ctrl-C / SIGTERM while importing rclpy / CasADi
        return 0
    finally:
        ignore_signals_at_exit()


__all__ = ["main"]
