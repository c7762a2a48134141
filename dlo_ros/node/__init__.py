"""The dlo ROS 2 node (issue 3): ``python -m dlo_ros.node``, ``ros2 run dlo_ros dlo_node``.

Also started by launch/dlo.launch.py.  Modules: ``dlo_node`` (the Node: ROS handles, the engine's
callbacks), ``run`` (``main``), ``startup`` (parameters, scene, first problem), ``engine`` (the
single solver worker thread and its "latest pending targets" slot), ``target_inputs``,
``shape_outputs`` (centreline, wrenches, markers), ``diagnostics``, ``shape_services``
(``~/query_shape``, ``~/reset``), ``live_parameters``, ``stream_log`` (recording and model
changes), ``qos``, ``conversions`` (messages <-> numpy), ``validation`` (target checks),
``params`` (parameter table, checks, command line), ``health`` (diagnostics content and warning
throttling), ``client`` (node subprocess, domain-id leases and a small client, used by the demo,
the benchmark and the tests), ``demo`` (the dual-arm demo job, ``run_demo_job``), and for
identification (``fit.enabled``) ``cloud`` (PointCloud2 → points), ``fitting`` (what is fitted and
when it is applied) and ``fit_node`` (``~/observed``, ``~/fit``).  Interfaces: msg_docs/node.md.
Importing this package does not import rclpy; its ROS modules do.
"""

from __future__ import annotations

import faulthandler
import sys

from ..blas_threads import one_blas_thread
from ..casadi_threads import CasadiUnsupported
from .signals import ignore_signals_at_exit, stop_on_first_signal


def main(argv: list[str] | None = None, prog: str = "python -m dlo_ros.node") -> int:
    """Run the node (the ``dlo_node`` console script); see dlo_ros.node.run.main.

    SIGINT and SIGTERM stop it with exit code 0 from the first moment (see
    :mod:`dlo_ros.node.signals`).
    """
    stop_on_first_signal()
    faulthandler.enable()  # a crash in native code prints every thread's Python stack
    one_blas_thread()  # before numpy loads (blas_threads.py)
    try:
        # not at the top: the signal handling above must be in place before rclpy and CasADi load
        from .run import main as _main

        return _main(argv, prog=prog)
    except CasadiUnsupported as exc:  # one line naming the fix (casadi_threads.py)
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # Ctrl-C / SIGTERM while importing rclpy / CasADi
        return 0
    finally:
        ignore_signals_at_exit()


__all__ = ["main"]
