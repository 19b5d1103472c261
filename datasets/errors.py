"""Errors raised by the dataset readers."""

from __future__ import annotations

from streetaug.augment.core import InputError


class DatasetError(InputError):
    """A dataset on disk is missing, incomplete or inconsistent.

    The message names the file (or table and token), what was expected, and what to do.
    """
