"""``python -m rhmpc.cli``: the console script."""

import sys

from rhmpc.cli import main

sys.exit(main())
