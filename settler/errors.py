"""The errors the command line answers with one line and exit status 2 (refused input). Kept in a module that
imports nothing, so that ``settler --help`` and the command line's error handling load neither NumPy nor Numba;
:mod:`settler.cases` and :mod:`settler.output` export them under their usual names."""


class CaseError(ValueError):
    """A case file, property set or override that cannot be accepted; the message says why."""


class OutputError(ValueError):
    """An output folder that cannot be used; the message says why and what to do."""
