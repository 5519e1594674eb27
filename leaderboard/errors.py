"""Errors raised while submitting to, or reading from, the leaderboard.

Every message names the offending value and what is allowed, so that the CLI can
print it as is.
"""

from __future__ import annotations


class SubmissionError(Exception):
    """A submission was refused; the store is unchanged."""


class InvalidSubmission(SubmissionError):
    """The submission does not pass validation (schema, suite coverage, metric bounds, sizes)."""


class VerificationFailed(SubmissionError):
    """Re-running a sample of the episodes failed or did not reproduce the submitted metrics.

    Attributes:
        report: The :class:`~swarmloc.leaderboard.verify.verification.VerificationReport` when the
            re-run finished but metrics differ; ``None`` when the worker failed.
    """

    def __init__(self, message: str, report: object | None = None) -> None:
        super().__init__(message)
        self.report = report


class SandboxUnavailable(SubmissionError):
    """Submitted code cannot be isolated here (no bubblewrap, no user namespaces, not Linux).

    The message names the tool, what is missing, and the ``--no-sandbox`` opt-in.
    """


class DuplicateSubmission(SubmissionError):
    """The same method (by hash) is already on the leaderboard for this suite."""


class StoreError(Exception):
    """The leaderboard store cannot be opened or has an unsupported schema version."""


__all__ = [
    "DuplicateSubmission",
    "InvalidSubmission",
    "SandboxUnavailable",
    "StoreError",
    "SubmissionError",
    "VerificationFailed",
]
