"""analysis: what is done with stored runs, apart from the engines.

- :mod:`analysis.figures`: the seed paper's figures (Jylhä & Jokilaakso, Heliyon 2023) drawn from a ``settler
  full`` run folder (``settler figures RUN``); it reads files only and imports no engine.

Under construction: comparison of reduced (popbal) with full (fulldem) runs, and calibration (needs runs from both
engines).
"""
