"""cpmp's Hydra configs, installed as the package ``cpmp._conf`` (see setup.py).

This file only makes the folder a package, as ``importlib.resources`` and Hydra's
``pkg://cpmp._conf`` search path need; the configs are the YAML files beside it.
"""
