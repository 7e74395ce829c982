"""mocapfix — batch cleaning of motion-capture files.

The public Python API mirrors the command line::

    import mocapfix
    motion = mocapfix.read("trial.c3d")
    mocapfix.write(motion, "out/trial.c3d")
"""
from mocapfix.core.errors import MocapfixError
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.core.version import __version__
from mocapfix.formats import read, write

__all__ = ["Motion", "Skeleton", "MocapfixError", "read", "write", "__version__"]
