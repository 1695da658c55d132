"""``python -m rhmpc.cli``: the console script."""

import sys

from rhmpc.cli import main

if __name__ == "__main__":  # importing the module (autosummary does) must not run the CLI
    sys.exit(main())
