"""Errors the runtime raises: each names the problem and, for elements, their ids."""
from __future__ import annotations

import numpy as np


class TensormassError(ValueError):
    """Base class: bad input that the user can fix (exit code 2 on the command line)."""


class SceneError(TensormassError):
    """A scene file that cannot be used; the message names the key."""


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


# Exit codes of the command line (README, "Exit codes").
EXIT_OK = 0              # ran; the result is within the health limits (warnings, if any, printed and in the summary)
EXIT_INTERNAL = 1        # a bug in tensormass: one line naming it (TENSORMASS_DEBUG=1 shows the traceback)
EXIT_BAD_INPUT = 2       # bad input or environment (scene, mesh, paths, resources, cache); nothing was simulated
EXIT_UNTRUSTED = 3       # ran, but the result is not one we stand behind (stopped, failed, or invalid at the end)
EXIT_INTERRUPTED = 130   # Ctrl-C: the frames so far are kept, the summary says "interrupted"


class RunStopped(TensormassError):
    """A run that started stepping and ended without a result we stand behind.

    status: "diverged" (the health monitor stopped it: NaN, energy blow-up, absurd
    displacement), "failed" (a step could not be solved), "invalid" (it finished,
    but its final state is outside the trusted region, e.g. inverted elements).
    summary: the run's Summary up to that point (status, warnings, health, message).
    """
    exit_code = EXIT_UNTRUSTED

    def __init__(self, message: str, summary=None, status: str = "diverged"):
        super().__init__(message)
        self.summary = summary
        self.status = status


class RunInterrupted(RunStopped):
    """Ctrl-C during the steps: the summary up to the last finished step, status "interrupted"."""
    exit_code = EXIT_INTERRUPTED

    def __init__(self, message: str = "interrupted", summary=None):
        super().__init__(message, summary, status="interrupted")
