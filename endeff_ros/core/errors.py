"""Errors raised by the algorithm core: one class per kind of problem, message built first."""

from __future__ import annotations


class EndeffError(Exception):
    """Base class of every error endeff_ros raises on purpose."""


class InputError(EndeffError, ValueError):
    """The input frame is unusable (encoding, intrinsics, sizes, no valid depth...)."""


class ParameterError(EndeffError, ValueError):
    """A parameter is unknown, of the wrong type or out of range."""
