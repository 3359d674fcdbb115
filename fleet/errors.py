"""Errors that reach the user as one clear line (no traceback)."""


class UserError(Exception):
    """Bad input from the user: a file, a flag, a name. The message says what and why."""
