"""CliError, the one-line error of every command (exit status 2), in a module of its own: the class is the same
whether sgim.cli is imported or run as ``python -m sgim.cli`` (a class defined in a module run as __main__ would
be a second class, not caught as the first)."""


class CliError(Exception):
    """One-line error for the user (exit status 2)."""
