"""``python -m holescan.cli``: the same as the ``holescan`` command."""

import sys

from holescan.cli import main

sys.exit(main())
