"""Drivers for real hardware behind the protocols of ``devices.protocols``.

Each driver is its own module and imports its vendor package only when a device is opened (a missing
package is a :class:`devices.drivers.common.MissingVendorPackageError` naming the pip extra):

- ``realsense``  Intel RealSense depth camera (``pyrealsense2``, extra ``[realsense]``)
- ``rsrecord``   write depth images into a RealSense recording (software device + recorder)
- ``ur``         Universal Robots arm over RTDE (``ur-rtde``, extra ``[ur]``)
- ``grbl``       stepper turntable on GRBL firmware over a serial port (``pyserial``, extra ``[turntable]``)
- ``modbus``     turntable on a Modbus RTU position drive (``minimalmodbus``, extra ``[turntable]``)
- ``plate``      plate angle <-> controller units, shared by the turntables
- ``limits``     joint limits checked before a trajectory is sent
- ``common``     lazy vendor imports, ArmFaultError
- ``registry``   driver names of the cell file -> config class + factory

Importing this package imports no vendor package.
"""
