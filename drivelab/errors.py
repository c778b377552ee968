"""The one error type users see: a single line naming what is wrong."""


class UsageError(ValueError):
    """Bad input from the user (unknown name, impossible combination, malformed file): the CLI
    prints ``error: <message>`` and exits with code 2, before writing anything."""
