"""Test support shared by test/unit and test/ros (importable as ``support``: test/conftest.py puts
test/ on sys.path). Not part of the dlo_ros package.

* :mod:`support.problems`: small problems built from the model classes (no YAML, no ROS).
* :mod:`support.node`: the node tests' scene and model (from the environment), process helpers and
  :func:`support.node.clean_node`.
"""
