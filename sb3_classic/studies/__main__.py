"""``python -m sb3_classic.studies``: see ``sb3_classic.studies.cli``."""

import sys

from sb3_classic.studies.cli import main

if __name__ == "__main__":
    sys.exit(main())
