"""``python -m service.migrations ACTION``: the same as ``hockle db ACTION``."""
from __future__ import annotations

import sys

from service.migrations.cli import main

if __name__ == "__main__":
    sys.exit(main())
