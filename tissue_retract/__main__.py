"""``python -m tissue_retract`` runs the ``tissue-retract`` command line."""

from tissue_retract.cli import main

if __name__ == "__main__":  # a spawned worker process imports this module under another name
    raise SystemExit(main())
