"""``python -m hockle``: the ``hockle`` command."""
import sys

from hockle.cli import main

if __name__ == "__main__":
    sys.exit(main())
