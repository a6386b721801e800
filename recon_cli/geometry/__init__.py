"""Geometry: rigid transforms and the camera views of the thesis (section 2.1)."""
