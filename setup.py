"""Which packages the wheel holds (the metadata is in pyproject.toml).

Every ``cpmp`` package, and the top-level ``conf/`` folder installed as the package
``cpmp._conf``: the Hydra configs travel in the wheel, and an editable install
(``pip install -e .``) maps ``cpmp._conf`` onto the checkout's ``conf/`` itself, so edits
there take effect. ``cpmp.config.paths`` finds it with ``importlib.resources``.
"""

from setuptools import find_namespace_packages, setup

NOT_PACKAGES = ["__pycache__", "*.__pycache__"]
CONF = [
    "cpmp._conf",
    *(f"cpmp._conf.{group}" for group in find_namespace_packages("conf", exclude=NOT_PACKAGES)),
]

setup(
    packages=[*find_namespace_packages(include=["cpmp", "cpmp.*"], exclude=NOT_PACKAGES), *CONF],
    package_dir={"cpmp._conf": "conf"},
)
