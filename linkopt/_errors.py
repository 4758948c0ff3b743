"""Errors raised at the library's boundary (file loading, argument checking).

Inside traced code failures are values (a converged flag and a residual); these
exceptions are for input a user can fix, and their message is one line that names
the file, the table/field and what was expected.
"""


class LinkoptError(Exception):
    """Base class of every error linkopt raises on purpose."""


class MechanismFileError(LinkoptError):
    """A mechanism definition file is malformed or inconsistent."""

    def __init__(self, source: str, where: str, message: str):
        self.source = source
        self.where = where
        self.message = message
        location = f"{source}: {where}: " if where else f"{source}: "
        super().__init__(location + message)


class InputError(LinkoptError):
    """A value passed to the API or the command line has the wrong shape or content."""
