"""The one exception tree of fracas (edges only: config, io, cli).

Every message names the file, the field, the value and what was expected; the command
line prints it on one line and exits non-zero (traceback only under ``--debug``).
"""

from __future__ import annotations


class FracasError(Exception):
    """Base class of every error fracas reports to a user.

    ``problems``: every problem found, one line each (``source: field = value: expected``);
    ``str(exc)`` stays the first of them plus " (and N more errors)".  An error raised with
    a message only has ``problems == [message]``.  A message is always one line: line breaks
    (a library's message quoted in it, e.g. the HDF5 library's) become spaces.
    """

    exit_code = 2

    def __init__(self, *args: object, problems: list[str] | None = None) -> None:
        if args and isinstance(args[0], str) and ("\n" in args[0] or "\r" in args[0]):
            args = (" ".join(args[0].split()), *args[1:])  # one line, whatever a library said
        super().__init__(*args)
        if problems:
            self.problems = list(problems)
        else:
            self.problems = [str(args[0])] if args else []


class DeckError(FracasError):
    """A deck cannot be read or does not validate."""


class ConfigError(FracasError):
    """A validated deck asks for something the core cannot do (unknown body, time outside ephemeris)."""


class StmFileError(FracasError):
    """An STM file is missing, unreadable, incomplete or built from another trajectory."""


class ResultsFileError(FracasError):
    """A results file is missing, unreadable, of another kind or incomplete."""


class OutputPathError(FracasError):
    """An output path cannot be written (a directory, an unwritable or impossible folder, empty).

    ``reason``: the cause alone, without the path (for callers that name the deck field)."""

    def __init__(self, *args: object, reason: str = "", **kw: list[str] | None) -> None:
        super().__init__(*args, **kw)
        self.reason = reason or (str(args[0]) if args else "")


class ConvergenceError(FracasError):
    """An iteration (Kepler, event location, targeting) did not converge."""


class NumericalError(FracasError):
    """A propagation or covariance failed numerically (NaN, loss of positive-definiteness)."""
