"""``python -m service``: serve the API (embedded worker included when no broker is set)."""
from __future__ import annotations

import sys

from service.serve import main

if __name__ == "__main__":
    sys.exit(main())
