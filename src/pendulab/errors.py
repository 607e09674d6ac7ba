"""Errors that pendulab reports to users.

Every mistake a user can make (a bad flag, a malformed controller or calibration file, a log that
cannot be used) raises :class:`UserError`. The command line turns it into one line on stderr and exit
status 2; the Python API lets it propagate so scripts can catch it.
"""

from __future__ import annotations


class UserError(ValueError):
    """A problem with user input; the message says what is wrong and how to fix it."""

    exit_status = 2


class ParameterError(UserError):
    """A physical parameter is out of range (negative mass, non-finite value, ...)."""


class ControllerError(UserError):
    """A controller violates the entry rules of SPEC §4."""


class CalibrationError(UserError):
    """A calibration file or a calibration log cannot be used."""


class FitRejected(CalibrationError):
    """A fit whose answer is not a calibration: a parameter the logs cannot identify, or values whose
    forward simulation misses the log by far more than the encoder step. Exit status 3."""

    exit_status = 3


class FmuBuildError(RuntimeError):
    """Building native code (an FMU, a compiled helper) failed: no C compiler, or a compiler error."""
