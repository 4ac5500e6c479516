"""Errors the runtime raises: each names the problem and, for elements, their ids."""
from __future__ import annotations

import numpy as np


class TensormassError(ValueError):
    """Base class: bad input that the user can fix (exit code 2 on the command line)."""


class ElementError(TensormassError):
    """A problem with specific elements; ``elements`` holds their ids (0-based)."""

    def __init__(self, message: str, elements):
        self.elements = np.asarray(elements, dtype=np.int64)
        ids = ", ".join(str(int(i)) for i in self.elements[:10])
        more = f" and {len(self.elements) - 10} more" if len(self.elements) > 10 else ""
        super().__init__(f"{message}: element(s) {ids}{more}")


class InvertedElementError(ElementError):
    """det F <= 0 at an integration point for a law that is undefined there."""


class DegenerateElementError(ElementError):
    """A rest element with det J <= 0 (inverted or flat) or unusable for the requested rule."""


class KernelNotFoundError(TensormassError):
    """No generated kernel and no way to generate it."""
