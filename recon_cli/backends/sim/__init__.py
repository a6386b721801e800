"""The MuJoCo simulation backend: the cell of robot/ with a rendered RGB-D camera."""
