"""rhmpc: receding-horizon MPC for robot-assisted beating-heart surgery."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rhmpc")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

