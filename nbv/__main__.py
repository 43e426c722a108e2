"""``python -m nbv``: the ``nbv`` command."""

import sys

from nbv.cli import main

if __name__ == "__main__":
    sys.exit(main())
