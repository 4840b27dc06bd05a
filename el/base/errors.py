"""The project's own exception classes, under one root (:class:`UavElError`).

A caller catches the project's named failures (bad data, weights, cards, models, budget) with one
``except UavElError`` (``assurance.errors`` adds the harness's on the same root). The input errors are
also ``ValueError``, and a bad argument to a function raises a plain ``ValueError`` or ``TypeError``:
``except ValueError`` catches both, ``except UavElError`` only the named ones.
"""

from __future__ import annotations


class UavElError(Exception):
    """Root of the exceptions that ``el`` and ``assurance`` raise on purpose."""


class DataError(UavElError, ValueError):
    """A data file or folder is missing, unreadable or inconsistent; the message names it."""


class LabelColourError(UavElError, ValueError):
    """A label image holds colours that are not UAVid class colours."""


class WeightsError(UavElError, ValueError):
    """A weights file or its model card is missing, altered or unusable; the message names it."""


class CalibrationError(UavElError, ValueError):
    """A calibration card that cannot be used (missing, unreadable, altered, inconsistent)."""


class FrameGateError(UavElError, ValueError):
    """A frame-gate file (``uav-el fit-gate``) that cannot be used (missing, unreadable, altered, inconsistent)."""


class LearnedModelError(UavElError, ValueError):
    """A learned-monitor model file that cannot be used (missing, unreadable, altered, inconsistent)."""


class BudgetExceeded(UavElError):
    """The decision's time budget ran out (turned into the default action with reason 'timeout')."""
