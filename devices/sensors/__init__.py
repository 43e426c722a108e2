"""Depth-sensor models of the simulated camera (docs/experiments/sensors.md, "Sensor models").

- ``presets``        SensorModel, SENSORS (ideal, realsense-d435, realsense-d405, structured-light), sensor_named
- ``depth_effects``  grazing incidence, range, flying pixels, depth noise, holes, quantisation: apply_effects
- ``occlusion``      second_view_visible: the other imager's / projector's line of sight
"""

from devices.sensors.depth_effects import apply_effects
from devices.sensors.occlusion import second_view_visible
from devices.sensors.presets import SENSORS, SensorModel, sensor_named

__all__ = [
    "SENSORS",
    "SensorModel",
    "apply_effects",
    "second_view_visible",
    "sensor_named",
]
