"""The installed distribution's version (`bsfjax --version`, `bsfjax.__version__`)."""

from importlib.metadata import PackageNotFoundError, version

try:
    VERSION = version("bsfjax")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    VERSION = "0.0.0+unknown"
