"""PyBullet simulation of soft-tissue retraction with the dVRK PSM.

Importing the package registers the Gymnasium environments ``TissueRetract-Lift-v0``,
``-Target-v0``, ``-MultiSite-v0`` and ``-Expose-v0``.
"""

from sim.registration import register as _register

_register()
