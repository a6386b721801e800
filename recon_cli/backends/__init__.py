"""Backends: the only place where simulation and hardware differ (base.py has the interfaces)."""
