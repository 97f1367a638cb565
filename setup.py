"""Package discovery for setuptools (metadata lives in pyproject.toml).

kernels/ and schedulers/ stay at the top level of the repository (DESIGN.md) and ship inside the package as
couplekit.kernels and couplekit.schedulers; every other couplekit.* package is found automatically.
"""

from setuptools import find_packages, setup

TOP_LEVEL = {"couplekit.kernels": "kernels", "couplekit.schedulers": "schedulers"}

setup(
    packages=find_packages(include=["couplekit", "couplekit.*"]) + list(TOP_LEVEL),
    package_dir=TOP_LEVEL,
)
