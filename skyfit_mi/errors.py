"""The project's exception types: every error on bad user input is a :class:`SkyfitError` (a
``ValueError``) whose message says what was wrong and how to fix it."""

import numpy as np


class SkyfitError(ValueError):
    """Base class of every error raised on bad input to skyfit-mi."""


class InputRangeError(SkyfitError):
    """A number lies outside its valid range (the message names the range)."""


class UnknownNameError(SkyfitError):
    """A name (sky type, method, normalisation...) is not one of the valid ones."""


class ParseError(SkyfitError):
    """A text description (e.g. Radiance ``gensky`` output) could not be read."""


class OutputError(SkyfitError):
    """An output path cannot be written (the message names the path and the reason)."""


class SetupError(RuntimeError):
    """The rendering back-end cannot start (missing libLLVM, no GPU...)."""


def listed(names, most=3):
    """``names`` joined for a message: the first ``most``, then how many more."""
    names = list(names)
    return ", ".join(names[:most]) + (f" and {len(names) - most} more" if len(names) > most
                                      else "")


def check_range(name, value, lo, hi, unit=""):
    """Raise :class:`InputRangeError` unless ``lo <= value <= hi`` everywhere (NaN fails)."""
    v = np.asarray(value, dtype=float)
    if v.size and not (np.all(v >= lo) and np.all(v <= hi)):
        bad = v[~((v >= lo) & (v <= hi))].ravel()[0]
        u = f" {unit}" if unit else ""
        raise InputRangeError(
            f"{name} = {bad:g}{u} is outside the valid range [{lo:g}, {hi:g}]{u}; "
            f"give a value in that range."
        )
    return value


def check_choice(name, value, choices):
    """Raise :class:`UnknownNameError` unless ``value`` is one of ``choices``."""
    if value not in choices:
        valid = ", ".join(repr(c) for c in choices)
        raise UnknownNameError(f"unknown {name} {value!r}; valid values are: {valid}.")
    return value
