"""User-facing errors: the CLI prints them as one line and exits with code 2, never a traceback."""


class FlighttestError(Exception):
    """Bad input or refused operation, explained in one line for the person at the keyboard."""

    exit_code = 2
