"""``python -m tissue_retract`` runs the ``tissue-retract`` command line."""

from tissue_retract.cli import main

raise SystemExit(main())
