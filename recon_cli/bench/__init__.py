"""Benchmarks of the thesis' chapter 4 and of our own components (``recon bench ...``)."""
