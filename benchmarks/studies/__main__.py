"""``python -m benchmarks.studies``: ``python -m sb3_classic.studies`` with the repository's folders."""

import sys

from benchmarks.studies import main

if __name__ == "__main__":
    sys.exit(main())
