"""Training of the learned sky (:mod:`streetaug.augment.lighting.skynet`): data the project makes and the loops.

Not product code: ``streetaug train-sky`` / ``train-light`` run it; the product only loads the weights it
writes (``lighting/skynet/weights``, see the model card there). :mod:`.synth` makes procedural skies,
:mod:`.data` the training and evaluation views (street scenes rendered with :mod:`streetaug.augment.scenegen`
under random skies, crops of real panoramas, synthetic-sky crops), :mod:`.train` the reproducible, resumable
training loops and their configurations.
"""

from .train import LightTrainConfig, SkyTrainConfig, TrainConfig, train_light, train_sky

__all__ = ["LightTrainConfig", "SkyTrainConfig", "TrainConfig", "train_light", "train_sky"]
