"""Perception: camera models, RGB-D to points, ChArUco board, cropping."""
