"""``python -m service.cli``: the ``millwatch`` command line (:func:`service.cli.main.main`)."""

from __future__ import annotations

import sys

from service.cli.main import main

sys.exit(main())
