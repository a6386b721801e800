"""Hardware adapters behind the backend interfaces (recon_cli/backends/base.py).

    ads.py        the robot over Beckhoff TwinCAT ADS (pyads): setpoint download, watchdog, stop
    genicam.py    GenICam/GenTL 3D cameras through harvesters (Photoneo and others)
    realsense.py  Intel RealSense depth cameras (pyrealsense2)
    replay.py     recorded frames (scan stores, folders of colour/depth images)
    station.py    a station of a robot adapter and a camera adapter from a station file

Each driver library is an optional extra; a missing one is a one-line hint.
"""
