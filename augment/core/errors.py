"""Error types and the shape check every module uses.

* :class:`InputError`: bad user input (a file, a field, an option); the message names the file, the field
  and what was expected. The CLI turns it into one line on stderr and exit code 1.
* :class:`ConventionError`: an array does not have the shape or values a convention requires.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np


class InputError(ValueError):
    """Bad user input: names the file, the field and what was expected."""


class ConventionError(ValueError):
    """Raised when an array does not have the shape or values a convention requires."""


def check_shape(x: np.ndarray, shape: Sequence[int | str], name: str) -> None:
    """Raise a clear error unless ``x`` has ``shape``; strings in ``shape`` match any size.

    Example: ``check_shape(points, ("N", 3), "points_ego")``.
    """
    actual = tuple(np.shape(x))
    ok = len(actual) == len(shape) and all(
        isinstance(want, str) or want == got for want, got in zip(shape, actual)
    )
    if not ok:
        want = "(" + ", ".join(str(s) for s in shape) + ")"
        raise ConventionError(f"{name}: expected shape {want}, got {actual}")


def check_rays(points, dirs) -> None:
    """Raise a clear error unless ray origins ``points`` and directions ``dirs`` are both (N, 3) with the same N
    (numpy arrays or tensors)."""
    check_shape(points, ("N", 3), "points")
    check_shape(dirs, ("N", 3), "dirs")
    if len(points) != len(dirs):
        raise ValueError(f"points and dirs must have the same length, got {len(points)} and {len(dirs)}")
