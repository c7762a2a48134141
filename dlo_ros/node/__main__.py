"""``python -m dlo_ros.node [--params-file FILE] [--scene NAME] [--ros-args ...]``"""
import sys

from . import main

if __name__ == "__main__":
    sys.exit(main())
