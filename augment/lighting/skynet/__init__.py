"""The learned sky model and single-image sky predictor (issue 5; see ``MODEL_CARD.md`` beside this file).

Modules: :mod:`.dome` (sky-dome geometry, panoramas, peaks), :mod:`.synth` (procedural training skies),
:mod:`.model` (networks), :mod:`.weights` (safe weight files), :mod:`.data` and :mod:`.train` (training
data and loops of ``streetaug train-sky`` / ``train-light``), :mod:`.predict` (inference API:
``predict_sky``, ``refine_sky``, ``sky_to_light``).  Importing this package does not import torch.
"""
