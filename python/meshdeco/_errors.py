"""The exceptions of meshdeco. Every one derives from :class:`Error`; most also derive from
the built-in exception a Python user expects (``ValueError``, ``FileNotFoundError``, …), so
``except ValueError`` keeps working. The message is the library's: it names the file (and
line), the config key (``method.<key>``) or the argument, and the bad value."""

from __future__ import annotations


class Error(Exception):
    """Base class of every meshdeco error."""


class FileNotFound(Error, FileNotFoundError):
    """A file or directory does not exist (the message names it)."""


class FileError(Error, OSError):
    """A file could not be read or written (permissions, a directory where a file was expected, …)."""


class ParseError(Error, ValueError):
    """A mesh or other input file is malformed, or frames do not share one connectivity."""


class ConfigError(Error, ValueError):
    """A config key has an invalid value (the message names ``data.<key>`` / ``method.<key>``)."""


class InvalidInput(Error, ValueError):
    """An input or hyperparameter is out of its valid range (the message carries the value)."""


class ArgumentError(Error, ValueError):
    """A Python argument has the wrong shape or value; the message starts with its name."""


class ArgumentTypeError(Error, TypeError):
    """A Python argument has the wrong type or dtype; the message starts with its name."""


class NumericalError(Error, ArithmeticError):
    """A numerical failure (a factorisation failed, non-finite values appeared)."""


__all__ = [
    "Error",
    "FileNotFound",
    "FileError",
    "ParseError",
    "ConfigError",
    "InvalidInput",
    "ArgumentError",
    "ArgumentTypeError",
    "NumericalError",
]
