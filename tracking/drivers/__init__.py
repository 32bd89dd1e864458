"""Drivers around the per-frame math: they read files, run the tracker and write or score results.

``offline`` (``rehab track``: a recording folder frame by frame to result files), ``bench``
(``rehab bench``), ``evaluate`` (measured points against the simulator's truth),
``calibration_check`` (one recording tracked with two calibrations) and ``wand_capture`` (wand ball
centroids from a wand recording). The per-frame math never imports this package.
"""
