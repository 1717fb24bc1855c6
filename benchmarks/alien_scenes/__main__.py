"""``python benchmarks/alien_scenes OUT --n N --seed S [--jobs J]``."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: the package's parent

from alien_scenes.cli import main

raise SystemExit(main())
