"""``python -m streetaug.cli`` = the ``streetaug`` command."""

from .main import main

main()
