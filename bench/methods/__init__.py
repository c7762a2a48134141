"""The bench's own solvers (planar Ritz and rod, 3D quaternion rod, the paper's multiplier method) and the
dynamic peers (PyElastica, MuJoCo), behind one interface (``runners.make_runner``)."""
