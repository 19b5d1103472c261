"""The learned sky model and single-image sky predictor (issue 5; see ``MODEL_CARD.md`` beside this file).

Modules: :mod:`.dome` (sky-dome geometry, panoramas, peaks), :mod:`.model` (networks), :mod:`.weights` (safe
weight files and the shipped models' loaders), :mod:`.inputs` (the predictor's input view and rays),
:mod:`.sun_cues` (explicit sun cues: disc, clear-sky fit), :mod:`.predict` (inference API: ``predict_sky``,
``refine_sky``, ``sky_to_light``, ``estimate_sky_light``). Training lives in :mod:`streetaug.augment.training`.
Importing this package does not import torch.
"""

__all__ = ["dome", "inputs", "model", "predict", "sun_cues", "weights"]  # modules (import them directly)
