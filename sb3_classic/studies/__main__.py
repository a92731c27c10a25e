"""``python -m benchmarks.studies``: see ``benchmarks.studies.cli``."""

import sys

from benchmarks.studies.cli import main

if __name__ == "__main__":
    sys.exit(main())
