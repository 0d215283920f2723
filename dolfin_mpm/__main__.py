"""``python -m dolfin_mpm``: the ``dolfin-mpm`` command line."""

import sys

from dolfin_mpm.app.cli import main

sys.exit(main())
