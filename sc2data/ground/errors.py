"""The one exception type the CLI turns into a one-line message and a non-zero exit."""

from __future__ import annotations

import os


class Sc2DataError(Exception):
    """Bad input or environment: the message says what is wrong and what to do.

    Library code raises it (or a subclass) for anything a user can fix: a wrong option, a
    malformed recipe, a foreign or damaged shard, a missing install. The CLI prints
    ``sc2data: error: <message>`` and exits with status 2, with no traceback.
    """


class MissingDependencyError(Sc2DataError):
    """An optional package is not installed; the message names the extra to install."""

    def __init__(self, package: str, extra: str, purpose: str) -> None:
        super().__init__(f"{purpose} needs the optional package {package!r}; install it with "
                         f"pip install 'sc2data[{extra}]'")


def reason(e: OSError) -> str:
    """An OS error in a few words, for a one-line message: its errno's text ("No space left on
    device"), else its first line (HDF5's own messages run over several)."""
    if e.errno:
        return os.strerror(e.errno)
    return (str(e.strerror or e).strip().splitlines() or [type(e).__name__])[0]
