"""``python -m assurance`` runs the ``uav-el`` command line.

``python -m`` puts the working directory first on ``sys.path``: run from an applicant's folder, a ``jsonschema.py``
(or ``yaml.py``, ``numpy.py``...) there would be imported instead of the library, running the applicant's code in
the auditor's process. The command line reads no module of the working directory, so that entry is dropped before
anything else is imported (``assurance/__init__.py``, run first, imports nothing; ``sys`` and ``os`` are built in
or imported at start-up, before the working directory is on the path).
"""

import os
import sys


def _drop_working_directory() -> None:
    """Remove the working directory (``''``, ``.`` or its absolute path, as ``python -m`` adds it) from
    ``sys.path``, unless it is the folder this package is imported from (a source checkout run in place)."""
    cwd = os.path.realpath(os.getcwd())
    home = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
    if cwd == home:
        return
    sys.path[:] = [p for p in sys.path if os.path.realpath(p or os.curdir) != cwd]


_drop_working_directory()

from assurance.cli import main  # noqa: E402  (after the path is cleaned)

sys.exit(main())
