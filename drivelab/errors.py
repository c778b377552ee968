"""The one error type users see: a single line naming what is wrong; and the type checks of a
user's value that run config fields, hyper-parameters, sensor options and saved counters share."""

import sys


class UsageError(ValueError):
    """Bad input from the user (unknown name, impossible combination, malformed file): the CLI
    prints ``error: <message>`` and exits with code 2, before writing anything."""


def is_number(value) -> bool:
    """Whether ``value`` is an int or a float (not a bool) of finite float size: not nan or inf, nor
    an int too large for a float (whose comparison here raises nothing, unlike ``math.isfinite``)."""
    return (
        isinstance(value, (int, float)) and not isinstance(value, bool) and abs(value) <= sys.float_info.max
    )


def like_default(value, default, what: str):
    """``value`` in the type of ``default``: true or false for a bool, an integer (an integral
    float becomes an int) for an int, a finite number for a float, a string for a string, a mapping
    for a dict; any value for another default (None, a list). Else the UsageError ``WHAT must be
    true or false`` (``an integer``, ``a number``, ``a string``, ``a mapping``) ``, got VALUE``."""
    if isinstance(default, bool):
        noun, fits = "true or false", isinstance(value, bool)
    elif isinstance(default, (int, float)):
        noun = "an integer" if isinstance(default, int) else "a number"
        fits = is_number(value) and (isinstance(default, float) or float(value).is_integer())
        value = type(default)(value) if fits else value
    elif isinstance(default, (str, dict)):
        noun = "a string" if isinstance(default, str) else "a mapping"
        fits = isinstance(value, type(default))
    else:
        return value
    if not fits:
        raise UsageError(f"{what} must be {noun}, got {value!r}")
    return value
