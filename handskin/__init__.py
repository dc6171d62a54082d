"""handskin: simulation-backed labelled tactile data for large-area robot skin."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("handskin")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+local"
