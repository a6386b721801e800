"""The robot cell: description (xacro), limits, kinematics, IK and collision model."""
