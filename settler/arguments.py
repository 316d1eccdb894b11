"""Command-line value types shared by the ``settler`` subcommands and the engines' option parsers.

A value typed on the command line is checked as strictly as the case key it stands for: a time must be a finite
number > 0 (``--end-time -1``, ``nan`` or ``inf`` are refused with a message naming the option, the value and what is
allowed, and the command exits 2 through argparse).
"""

from __future__ import annotations

import argparse
import math


def seconds(option: str, *, minimum: float = 0.0, smallest: float | None = None):
    """An argparse ``type`` for a simulated time [s]: a finite number > ``minimum`` (and >= ``smallest`` if given).

    argparse names the option in its message (``argument --end-time: -1: allowed: ...``); ``option`` is kept for
    callers that check a value outside argparse."""
    def parse(text: str) -> float:
        allowed = f"a finite number of seconds > {minimum:g}" + (f" and >= {smallest:g}" if smallest else "")
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number; allowed: {allowed}") from None
        if not math.isfinite(value) or value <= minimum or (smallest is not None and value < smallest):
            raise argparse.ArgumentTypeError(f"{text}: allowed: {allowed}")
        return value

    parse.__name__ = "seconds"  # argparse names the type in some messages
    return parse
