"""Package discovery for the repository layout.

The top-level folders map onto one import namespace (``harness/`` is
``canebench``, ``backends/`` is ``canebench.backends``, ...). Every package
below them is found by ``find_packages``, so a new subpackage can never be
left out of a wheel (``tests/test_install.py`` installs a wheel and runs a
trial). Everything else is in ``pyproject.toml``.
"""

from setuptools import find_packages, setup

ROOTS = {"canebench": "harness", "canebench.backends": "backends", "canebench.canes": "canes",
         "canebench.reports": "reports"}

packages = []
for name, path in ROOTS.items():
    packages.append(name)
    packages += [f"{name}.{sub}" for sub in find_packages(path)]

setup(packages=packages, package_dir=dict(ROOTS))
