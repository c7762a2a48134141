"""``python -m dlo_ros.node [--params-file FILE] [--scene NAME] [--check] [--ros-args ...]`` (also
``dlo node ...``)
"""

import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
