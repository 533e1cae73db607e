"""Placeholder (replaced by the run-status branch)."""
import enum


class RunStatus(enum.IntEnum):
    OK = 0
    STOPPED = 1
    MAX_STEPS = 2
    NONFINITE = 3
    OUTSIDE_TRAJECTORY = 5
    NOT_POSITIVE_DEFINITE = 6
    NONFINITE_COVARIANCE = 7


def status_text(code) -> str:
    return str(code)
