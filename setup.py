"""The package list; everything else is declared in setup.cfg.

Every package under ``mani_skill_space/`` is found automatically, so a new subpackage cannot be left out of
the wheel. Two packages live in top-level folders of the repository and are mapped in setup.cfg's
``package_dir``: ``mani_skill_space.assets`` (``assets/``) and ``mani_skill_space.tasks`` (``tasks/``, the
benchmark suites). setup.cfg's ``packages = find:`` only finds packages by their folders, so it would drop
those two; hence this file.
"""

from setuptools import find_packages, setup

MAPPED_PACKAGES = ["mani_skill_space.assets", "mani_skill_space.tasks"]
"""Packages whose folders sit outside ``mani_skill_space/`` (see setup.cfg's ``package_dir``)."""

setup(packages=find_packages(include=["mani_skill_space", "mani_skill_space.*"]) + MAPPED_PACKAGES)
