"""mocapfix — batch cleaning of motion-capture files.

The public Python API mirrors the command line::

    import mocapfix
    motion = mocapfix.read("trial.c3d")
    mocapfix.write(motion, "out/trial.c3d")
"""
from mocapfix.errors import MocapfixError
from mocapfix.motion import Motion, Skeleton
from mocapfix.formats import read, write

__version__ = "0.1.0"
__all__ = ["Motion", "Skeleton", "MocapfixError", "read", "write", "__version__"]
