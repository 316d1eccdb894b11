"""``python -m settler``: the ``settler`` command (settler.cli.main), exiting with its status."""

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
