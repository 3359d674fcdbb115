"""Errors that reach the user as one clear line (no traceback)."""


class UserError(Exception):
    """Bad input from the user: a file, a flag, a name. The message says what and why."""


def describe(exc: BaseException) -> str:
    """An expected failure as the user reads it: an OS error as 'PATH: why' (not
    '[Errno 2] ...'), anything else as its message."""
    if isinstance(exc, OSError) and exc.strerror:
        if exc.filename is None:
            return exc.strerror
        target = f" -> {exc.filename2}" if exc.filename2 is not None else ""
        return f"{exc.filename}{target}: {exc.strerror}"
    return str(exc) or type(exc).__name__
