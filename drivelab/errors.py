"""The one error type users see: a single line naming what is wrong; and the type check of a
user's value against its default, which hyper-parameters and sensor options share."""

import math


class UsageError(ValueError):
    """Bad input from the user (unknown name, impossible combination, malformed file): the CLI
    prints ``error: <message>`` and exits with code 2, before writing anything."""


def like_default(value, default, what: str):
    """``value`` in the type of ``default``: true or false for a bool, an integer (an integral
    float becomes an int) for an int, a finite number for a float, a string for a string, a mapping
    for a dict; any value for another default (None, a list). Else the UsageError ``WHAT must be
    true or false`` (``an integer``, ``a number``, ``a string``, ``a mapping``) ``, got VALUE``."""
    if isinstance(default, bool):
        noun, fits = "true or false", isinstance(value, bool)
    elif isinstance(default, (int, float)):
        noun = "an integer" if isinstance(default, int) else "a number"
        number = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        fits = number and (isinstance(default, float) or float(value).is_integer())
        value = type(default)(value) if fits else value
    elif isinstance(default, (str, dict)):
        noun = "a string" if isinstance(default, str) else "a mapping"
        fits = isinstance(value, type(default))
    else:
        return value
    if not fits:
        raise UsageError(f"{what} must be {noun}, got {value!r}")
    return value
