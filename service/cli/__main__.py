"""``python -m millwatch.cli``: the ``millwatch`` command line (:func:`millwatch.cli.main.main`)."""

from __future__ import annotations

import sys

from millwatch.cli.main import main

sys.exit(main())
