"""Supervised calibration of a cell: the routine of devices/calibration/ one approved pose at a time.

- ``run``   CalibrationRun: the poses (preview, approve, skip), the captures, the estimate, the write
- ``book``  Calibrations: the open calibrations of a server, each on its own (simulated or hardware) cell
"""

from workbench.calibration.book import Calibrations
from workbench.calibration.run import CalibrationRun, PosePreview, PoseState

__all__ = ["CalibrationRun", "Calibrations", "PosePreview", "PoseState"]
