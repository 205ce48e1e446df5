"""``python -m hsi_nodes.cli``: the ``hsi`` command line without the console script."""

from __future__ import annotations

import sys

from hsi_nodes.cli import main

if __name__ == "__main__":
    sys.exit(main())
