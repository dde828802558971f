"""What pyproject.toml cannot say: the Hydra configs, kept in the top-level conf/ of the checkout,
ship inside the distribution as the package data of `layerskin_exp.conf`, so an installed
wheel runs outside the checkout (layerskin_exp.cli.CONF_DIR finds either). benchmarks/ is not
installed.

Every folder under conf/ is named as a (data-only) package: setuptools otherwise warns that it
"would be ignored" and, in a later version, stops shipping it."""

from setuptools import find_namespace_packages, find_packages, setup

PACKAGES = find_packages(include=["layerskin_exp*", "hardware*", "protocols*", "analysis*"])
CONF = ["layerskin_exp.conf", *(f"layerskin_exp.conf.{p}" for p in find_namespace_packages(where="conf"))]
DATA = ["layerskin_exp.sim.fem_reference.reference"]  # data-only folders, named for the same reason

setup(
    packages=[*PACKAGES, *CONF, *DATA],
    package_dir={"layerskin_exp.conf": "conf"},
    package_data={
        "layerskin_exp": ["py.typed"],
        "layerskin_exp.sim.fem_reference.reference": ["*.npz", "*.json"],
        "": ["*.yaml", "*.md"],
    },
)
