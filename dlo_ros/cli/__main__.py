"""``python -m dlo_ros.cli ...``: the ``dlo`` command."""

import sys

from . import main

sys.exit(main())
