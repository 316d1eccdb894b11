"""popbal's hierarchical calibration against the reference set: the pre-registered hold-outs
(:mod:`~analysis.calibration.registry`), what runs are scored on (:mod:`~analysis.calibration.targets`), one
level's fit with its discrepancy and identifiability gate (:mod:`~analysis.calibration.fit`) and the levels in
order (:mod:`~analysis.calibration.hierarchy`). The older one-level fit of named cases is :mod:`analysis.calibrate`.
"""
