"""The project's one exception root; every package subclasses it."""


class HolescanError(Exception):
    """Root of every error holescan raises on purpose (the CLI prints it as one line)."""


class InputError(HolescanError, ValueError):
    """Bad input: wrong shape/dtype, missing or corrupt file. The message says what to fix."""
