"""``python -m helio_control``: the ``helio`` command (helio_control.cli)."""

import sys

from helio_control.cli import main

sys.exit(main())
