"""mocapfix — batch cleaning of motion-capture files.

The public Python API mirrors the command line::

    import mocapfix
    motion = mocapfix.read("trial.c3d")
    cleaned, report = mocapfix.clean(motion)                  # the default config
    cleaned, report = mocapfix.clean("trial.c3d", "optical-c3d", max_fill_error="30 mm")
    result = mocapfix.check("trial.c3d")                      # status, findings
    mocapfix.write(cleaned, "out/trial.c3d")
    motion = mocapfix.Motion.from_arrays(positions, names, fps=100.0)   # numpy (T, J, 3)

Folders and batches: :func:`mocapfix.batch.clean.clean_batch`.
"""
from mocapfix.api import check, clean, load_config
from mocapfix.core.errors import MocapfixError
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.core.version import __version__
from mocapfix.formats import read, write

__all__ = ["Motion", "Skeleton", "MocapfixError", "read", "write", "clean", "check",
           "load_config", "__version__"]
