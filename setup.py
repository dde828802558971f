"""What pyproject.toml cannot say: the Hydra configs, kept in the top-level conf/ of the checkout,
ship inside the distribution as the package data of `layerskin_exp.conf`, so an installed
wheel runs outside the checkout (layerskin_exp.cli.CONF_DIR finds either). benchmarks/ is not
installed."""

from setuptools import find_packages, setup

PACKAGES = find_packages(include=["layerskin_exp*", "hardware*", "protocols*", "analysis*"])

setup(
    packages=[*PACKAGES, "layerskin_exp.conf"],
    package_dir={"layerskin_exp.conf": "conf"},
    package_data={
        "layerskin_exp.conf": ["*.yaml", "*/*.yaml", "*/*/*.yaml"],
        "layerskin_exp": ["py.typed"],
        "layerskin_exp.sim.fem_reference": ["reference/*.npz", "reference/*.json"],
        "": ["*.yaml", "*.md"],
    },
)
