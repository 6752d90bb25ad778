"""A Griffe extension for the API pages: Sphinx roles in docstrings shown as code.

The docstrings name other objects the Sphinx way (``:class:`ControlChain```, ``:meth:`tick```), which
Markdown would print as typed. Each role becomes an inline code span of the name (``~`` dropped).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

ROLE = re.compile(r":(?:class|meth|func|data|mod|attr|exc|obj|const|ref):`~?([^`]+)`")


class SphinxRolesAsCode(griffe.Extension):
    """Rewrites ``:role:`name``` as ```name``` in every docstring."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        """Rewrite the object's docstring as it is loaded."""
        if obj.docstring is not None:
            obj.docstring.value = ROLE.sub(r"`\1`", obj.docstring.value)
