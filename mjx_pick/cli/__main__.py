"""``python -m mjx_pick.cli``: the same as the ``mjx-pick`` command."""

import sys

from mjx_pick.cli import main

sys.exit(main())
