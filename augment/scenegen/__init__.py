"""Bundled sample scenes: procedural streets rendered, scanned and written as a nuScenes dataset.

Entry point: :func:`streetaug.augment.scenegen.make.make_sample_scenes`.
"""
