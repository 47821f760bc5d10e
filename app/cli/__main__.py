"""``python -m app.cli ...``: the same as the ``scengen`` command."""

import sys

from app.cli.main import main

sys.exit(main())
