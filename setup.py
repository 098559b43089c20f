"""Map the repository's folders to installed package names that cannot collide with other distributions.

pyproject.toml holds the metadata; this file only renames: ``service/`` installs as ``pdeanim_service`` and
``worker/`` as ``pdeanim_worker`` (setuptools' declarative configuration cannot rename found packages). The
viewer's static folders are found as namespace packages of data files, so they install without warnings."""

from setuptools import find_namespace_packages, setup

FOLDERS = {"pdeanim": "pdeanim", "pdeanim_service": "service", "pdeanim_worker": "worker"}


def packages(name: str, folder: str) -> list[str]:
    """``name`` and every folder below ``folder`` (caches left out), as installed package names."""
    found = find_namespace_packages(folder, exclude=["*__pycache__*"])
    return [name, *(f"{name}.{package}" for package in found)]


setup(packages=[p for name, folder in FOLDERS.items() for p in packages(name, folder)], package_dir=FOLDERS)
