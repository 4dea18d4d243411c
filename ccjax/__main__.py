"""``python -m ccjax``: the ``ccjax`` command."""

import sys

from ccjax.cli import main

sys.exit(main())
