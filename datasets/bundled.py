"""The bundled generated scenes (made by ``streetaug make-samples``, committed under ``examples/``).

- the sample scenes (``examples/nuscenes-samples``, version ``v1.0-samples``): three scenes of one keyframe;
- the sequence scene (``examples/nuscenes-sequence``, version ``v1.0-sequence``): one scene of several
  keyframes whose tables also list the camera and LiDAR sweeps; the committed copy holds the keyframe files
  only (``streetaug make-samples --sequence --sweeps`` renders the sweep files too).
"""

from __future__ import annotations

import os
from pathlib import Path

from streetaug.augment.core import InputError

BUNDLED_VERSION = "v1.0-samples"
BUNDLED_SUBDIR = Path("examples") / "nuscenes-samples"
BUNDLED_SEQUENCE_VERSION = "v1.0-sequence"
BUNDLED_SEQUENCE_SUBDIR = Path("examples") / "nuscenes-sequence"


def _find(env_var: str, subdir: Path, version: str, what: str, command: str) -> Path:
    """The first of ``$env_var`` and the source checkout's ``subdir`` that holds ``version``."""
    candidates = []
    if os.environ.get(env_var):
        candidates.append(Path(os.environ[env_var]))
    candidates.append(Path(__file__).resolve().parents[1] / subdir)
    for root in candidates:
        if (root / version).is_dir():
            return root
    raise InputError(
        f"bundled {what} not found (looked in: {', '.join(str(c) for c in candidates)}); "
        f"generate them with `{command}` and "
        f"pass `--dataroot DIR --version {version}`, or set {env_var}=DIR"
    )


def bundled_dataroot() -> Path:
    """The dataroot of the bundled sample scenes.

    Looked up in ``$STREETAUG_SAMPLES``, then in the source checkout this package runs from.
    """
    return _find("STREETAUG_SAMPLES", BUNDLED_SUBDIR, BUNDLED_VERSION, "sample scenes",
                 "streetaug make-samples --out DIR")


def bundled_sequence_dataroot() -> Path:
    """The dataroot of the bundled sequence scene (version ``v1.0-sequence``).

    Looked up in ``$STREETAUG_SEQUENCE``, then in the source checkout this package runs from. Its sweep
    files may be absent (see :func:`streetaug.datasets.sweeps.sweeps_unavailable_reason`).
    """
    return _find("STREETAUG_SEQUENCE", BUNDLED_SEQUENCE_SUBDIR, BUNDLED_SEQUENCE_VERSION, "sequence scene",
                 "streetaug make-samples --sequence --out DIR")
