"""Run the node: ``python -m dlo_ros.node [--params-file FILE] [--scene NAME] [--check] ...``.

Also ``dlo node ...``; ROS arguments follow ``--ros-args``.
"""

import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
