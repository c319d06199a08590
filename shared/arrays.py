"""Type aliases of the numpy arrays the project passes around (shapes are in each docstring)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["F64", "F32", "I64", "U64", "Bool"]

F64 = NDArray[np.float64]
"""float64 array: coordinates in metres, times, rates."""
F32 = NDArray[np.float32]
"""float32 array: GPU vertex data, matrices."""
I64 = NDArray[np.int64]
"""int64 array: ids, counts, indices."""
U64 = NDArray[np.uint64]
"""uint64 array: varint payloads."""
Bool = NDArray[np.bool_]
"""bool array: masks."""
