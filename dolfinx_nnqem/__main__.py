"""``python -m dolfinx_nnqem`` runs the command line (see :mod:`dolfinx_nnqem.cli`)."""

import sys

from dolfinx_nnqem.cli import main

sys.exit(main())
