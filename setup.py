"""Packaging beyond what pyproject.toml can say: the top-level data folders (cells/,
robot/, schemas/, scripts_xml/, batches/, stations/) become package data of ``recon_cli._data`` in wheels, so that a
normal ``pip install .`` works from any folder (recon_cli/paths.py finds them)."""

from setuptools import find_packages, setup

DATA = ("cells", "robot", "schemas", "scripts_xml", "batches", "stations")

setup(
    packages=find_packages(include=["recon_cli", "recon_cli.*"]) + [f"recon_cli._data.{d}" for d in DATA],
    package_dir={f"recon_cli._data.{d}": d for d in DATA},
    package_data={f"recon_cli._data.{d}": ["*", "*/*"] for d in DATA},
    exclude_package_data={f"recon_cli._data.{d}": ["__pycache__/*"] for d in DATA},
)
