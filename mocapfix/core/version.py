"""The version of mocapfix (written into manifests and model files; the package and
``mocapfix --version`` show it)."""
__version__ = "0.1.0"
