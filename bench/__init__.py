"""The benchmarks of dlo_ros (not installed with the package; see bench/README.md).

``suite``: the speed-vs-accuracy suite and the paper's examples; ``methods``: the bench's own solvers and
the dynamic peers; ``perf``: solver, node and tool performance.  ``common``: what all three share.
"""
