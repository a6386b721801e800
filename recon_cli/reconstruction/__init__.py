"""Reconstruction: the scan store, registration, surface and evaluation."""
