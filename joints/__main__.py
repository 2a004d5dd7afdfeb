"""``python -m joints`` runs the ``joints`` command."""

import sys

from joints.cli import main

sys.exit(main())
