"""Set-ups of the verification cases, importable by the tests, analysis.verification and the verification report.

What belongs here: cases built in code with their analytic reference (the case files of the settler are in
``data/cases``): a single droplet settling (:mod:`.single_droplet`), collective settling of suspensions
(:mod:`.suspensions`), the falling cloud (:mod:`.cloud`) and a dilute bidisperse suspension (:mod:`.bidisperse`).
"""
