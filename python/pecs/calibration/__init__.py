"""Fitting a sensor to a real recording, and measuring how real simulated events look.

- `fit`: `calibrate`, sensor parameters fitted to a recording's APS frames and events over a
  span, scored on the rest (`CalibrationResult`).
- `background_fit`: `calibrate_noise`, leak, shot noise and hot pixels from a static scene.
- `realism`: the measures both use (count ratio, ON fraction, count-map and rate correlations,
  chamfer and Gaussian distances).
- `report`: the calibration report (markdown and figure).
"""

from pecs.calibration.background_fit import NoiseFit, calibrate_noise
from pecs.calibration.fit import CalibrationResult, calibrate

__all__ = ["CalibrationResult", "NoiseFit", "calibrate", "calibrate_noise"]
