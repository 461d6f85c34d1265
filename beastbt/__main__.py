"""``python -m beastbt``: the same command as ``beastbt``, every option included."""

import sys

from beastbt.cli import main

if __name__ == "__main__":
    sys.exit(main())
