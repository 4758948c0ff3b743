"""``python -m linkopt``: the command line (:func:`linkopt._cli.main.main`)."""

import sys

from ._cli.main import main

sys.exit(main())
