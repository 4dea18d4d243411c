"""``python -m ccjax.cli``."""

import sys

from ccjax.cli import main

sys.exit(main())
