"""A scenario option's declaration: its type, range, default and meaning, and the check of a
value (``drivelab.scenarios.options`` checks a user's options against a scenario's)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from drivelab.errors import UsageError


@dataclass(frozen=True)
class Option:
    """One setting of a scenario.

    :param name: the config key.
    :param kind: its type: ``int``, ``float`` (an int is a float too), ``bool``, ``str`` or
        ``dict``; a tuple of them when it takes several (``map``: a block string or a count).
    :param default: its value in the scenario's default configuration (traffic ``regular``, the
        scenario's first action kind).
    :param doc: what it does, one sentence.
    :param minimum: the smallest number allowed (``exclusive_minimum``: numbers above it only).
    :param maximum: the largest number allowed.
    :param choices: the values a string option takes.
    :param nullable: null (None) is a value; ``doc`` says what it means.
    :param traffic: the traffic levels set it (``Scenario.traffic``).
    :param expected: what a value must be, where the range fields cannot say it (``check``'s).
    :param check: a further check of a value that passed the type and range, raising a UsageError
        that names the key (``map``'s block letters, ``light_timings``' phases).
    """

    name: str
    kind: type | tuple[type, ...]
    default: Any
    doc: str
    minimum: float | None = None
    exclusive_minimum: bool = False
    maximum: float | None = None
    choices: tuple = ()
    nullable: bool = False
    traffic: bool = False
    expected: str = ""
    check: Callable[[Any], None] | None = field(default=None, repr=False, compare=False)

    @property
    def kinds(self) -> tuple[type, ...]:
        return self.kind if isinstance(self.kind, tuple) else (self.kind,)

    @property
    def type_name(self) -> str:
        """The type as the docs' tables show it: "int", "float", "bool", "str", "str | int"."""
        names = " | ".join(kind.__name__ for kind in self.kinds)
        return f"{names} | null" if self.nullable else names

    @property
    def range_text(self) -> str:
        """The allowed values in a few characters: "> 0", ">= 1", "[0, 1]", "train, test"."""
        if self.choices:
            return ", ".join(str(choice) for choice in self.choices)
        low = self.minimum
        if low is not None and self.maximum is not None:
            return f"{'(' if self.exclusive_minimum else '['}{_number(low)}, {_number(self.maximum)}]"
        if low is not None:
            return f"{'>' if self.exclusive_minimum else '>='} {_number(low)}"
        if self.maximum is not None:
            return f"<= {_number(self.maximum)}"
        return ""

    def describe(self) -> str:
        """What a value must be, as the error says it: "an integer >= 1", "a number in [0, 1]"."""
        if self.expected:
            text = self.expected
        elif self.choices:
            text = "one of " + ", ".join(repr(choice) for choice in self.choices)
        elif bool in self.kinds:
            text = "true or false"
        else:
            noun = {int: "an integer", float: "a number", str: "a string", dict: "a mapping"}[self.kinds[0]]
            limits = self.range_text
            text = f"{noun} in {limits}" if limits.startswith(("[", "(")) else f"{noun} {limits}".strip()
        return f"{text} or null" if self.nullable else text

    def validate(self, value: Any, scenario: str) -> None:
        """A UsageError naming the key and what it must be, unless ``value`` is one of its values."""
        if value is None and self.nullable:
            return
        if value is None or not self._accepts(value):
            raise UsageError(
                f"option {self.name!r} of scenario {scenario!r} must be {self.describe()}, got {value!r}"
            )
        if self.check is not None:
            self.check(value)

    def _accepts(self, value: Any) -> bool:
        if isinstance(value, (bool, np.bool_)):
            return bool in self.kinds
        if isinstance(value, (int, np.integer)) and (int in self.kinds or float in self.kinds):
            return self._in_range(float(value))
        if isinstance(value, (float, np.floating)) and float in self.kinds:
            return math.isfinite(value) and self._in_range(float(value))
        if isinstance(value, str) and str in self.kinds:
            return not self.choices or value in self.choices
        return isinstance(value, dict) and dict in self.kinds

    def _in_range(self, number: float) -> bool:
        low, high = self.minimum, self.maximum
        if low is not None and (number <= low if self.exclusive_minimum else number < low):
            return False
        return high is None or number <= high


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else str(value)
