"""``python -m psm_control`` runs the ``tissue-retract`` command line."""

from psm_control.cli import main

raise SystemExit(main())
