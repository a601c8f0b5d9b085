"""``python -m rtp.cli.export``: the ``rtp-export`` command."""

import sys

from ._export import export_main

__all__ = ["export_main"]

if __name__ == "__main__":
    sys.exit(export_main())
