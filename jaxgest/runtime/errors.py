"""User-facing errors.

Every error a user can cause with plausible input, or that the environment causes (an unreadable checkpoint,
a full or read-only disk, a workdir of another version), derives from :class:`JaxgestError`. The CLI catches
it, prints ``jaxgest: <message>`` as one line on stderr and exits with status 2 -- never a traceback.
Messages name the file (when there is one) and the problem.
"""

from __future__ import annotations


class JaxgestError(Exception):
    """Base class of every user-facing error (bad input, bad checkpoint, bad argument)."""


class DataError(JaxgestError):
    """A data file or folder is unusable (unknown layout, too short, NaN, wrong rate, ...)."""


class AudioError(DataError):
    """An audio file is unreadable, empty or contains NaN/inf samples."""


class CheckpointError(JaxgestError):
    """A workdir has no checkpoint, or its config/skeleton differs from what is asked for."""


class WriteError(JaxgestError):
    """A file or checkpoint cannot be written (disk full, read-only or missing folder, ...); nothing partial
    is left and what was there before is unchanged."""


class TrainingError(JaxgestError):
    """Training cannot continue (for example a non-finite loss)."""


class Interrupted(JaxgestError):
    """Training stopped by SIGINT or SIGTERM after saving a checkpoint at the interrupted step (see
    :func:`jaxgest.runtime.training.stop_on_signals`); the command line exits with ``status`` (128 + the signal
    number: 130 for SIGINT, 143 for SIGTERM)."""

    def __init__(self, message: str, signum: int):
        super().__init__(message)
        self.signum = int(signum)
        self.status = 128 + self.signum
