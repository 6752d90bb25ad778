"""``any`` and ``all`` of small boolean arrays, for the control chain's per-tick checks.

``np.any``, ``np.all`` and ``np.count_nonzero`` go through a Python layer (dispatch, keyword handling) that
costs as much as comparing six numbers; the ufuncs' own ``reduce`` does the same reduction without it. The
results are the same, NaN included (a comparison with NaN is False either way).
"""

from __future__ import annotations

import numpy as np

__all__ = ["all_of", "any_of"]

#: True when any element is true (``np.logical_or.reduce``).
any_of = np.logical_or.reduce
#: True when every element is true (``np.logical_and.reduce``).
all_of = np.logical_and.reduce
