"""``python -m assurance`` runs the ``uav-el`` command line."""

import sys

from assurance.cli import main

sys.exit(main())
