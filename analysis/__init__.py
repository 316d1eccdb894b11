"""analysis: comparison of reduced (popbal) with full (fulldem) runs, and calibration.

Under construction: needs runs from both engines.
"""
