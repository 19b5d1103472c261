"""streetaug package."""
