"""Errors whose message tells the user everything: the command line prints them on one line
(exit 2) without a traceback. Any other exception is a bug and is reported as one."""
from __future__ import annotations


class UserError(ValueError):
    """Bad input or a failed step the user can act on; the message names the file or key."""


class SequenceError(UserError):
    """Bad input data: the message names the file and the problem."""


class ConfigError(UserError):
    """A bad parameter, method, mask source or profile: the message names the key and what is
    expected."""


class BatchError(UserError):
    """Runs or notebooks of the batch failed (each is listed in the summary)."""


class Interrupted(Exception):
    """Ctrl-C or SIGTERM: work stopped, nothing half-written (exit 130)."""
