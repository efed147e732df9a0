"""User-facing errors: the CLI prints these as one clear line (no traceback) and exits 2."""


class UserError(Exception):
    """Bad input from the user (a file, a flag, a config). The message names the file and the problem."""

    user_error = True


class DataError(UserError):
    """A clip, mesh or dataset file is malformed."""
