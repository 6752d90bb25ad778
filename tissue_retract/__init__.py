"""The tissue-retract application: the ``tissue-retract`` command line and the work that composes several
packages (sweep workers that run a policy in the simulation).

Layers, bottom to top: ``psm_control`` < ``safety`` < ``sim`` < ``policies`` < ``hardware_if`` <
``tissue_retract``; each module imports only its own package and those below it.
"""

from psm_control import __version__

__all__ = ["__version__"]
