"""Evaluation, apart from the product path: how good and how fast the outputs are.

It owns the image metrics shared by the benchmarks and the commands (:mod:`.metrics`: PSNR, the
env-map log error), the speed/accuracy sweep of lighting levels x render presets behind ``streetaug
bench`` (:mod:`.speed_accuracy`), the perturbation report and failure cases behind ``streetaug
stability`` (:mod:`.stability`) and the renderer's independent reference, a Mitsuba 3 path tracer of
the same scene (:mod:`.reference`; needs ``mitsuba``, imported on first use). Nothing in the product
path imports this package.
"""

from .metrics import env_log_error, psnr_db

__all__ = ["env_log_error", "psnr_db"]
