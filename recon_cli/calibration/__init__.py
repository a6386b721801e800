"""Calibration from views of the ChArUco board (docs/calibration.md).

    views.py           the generated board views (tilt, azimuth, roll, distance, offset)
    goals.py           joint goals for them that keep the arm's posture
    observations.py    per scan: flange pose from the model's kinematics, board pose from the image
    handeye.py         OpenCV's hand-eye solvers, residuals, pose diversity
    refine.py          the solution refined together with the robot base's error
    intrinsics.py      camera calibration from ChArUco corners, its figure
    camera_file.py     a calibrated camera and its YAML file (and a realism profile using it)
    station_update.py  the hand-eye result written into a station file
    dataset.py         a data set made by anyone: images and robot poses (index, CSV, pose files), the mapping
    setups.py          eye-in-hand and eye-to-hand as one chain, refined by the corners' reprojection error

The workflows that record, calibrate and write are in recon_cli/workflows/calibrate.py.
"""
