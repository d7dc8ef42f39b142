"""JSON encoding of the numpy/path values that records and checkpoint metadata contain."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def json_default(o):
    """``json.dumps(default=...)`` hook: numpy scalars/arrays and paths as plain JSON values."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
