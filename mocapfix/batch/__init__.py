"""Batches of files: find the inputs (:mod:`~mocapfix.batch.discovery`), map them to
outputs and refuse what cannot be done safely (:mod:`~mocapfix.batch.plan`), run one task
per file over an executor (:mod:`~mocapfix.batch.tasks`, :mod:`~mocapfix.batch.executors`),
and the commands built on them: the clean batch (:mod:`~mocapfix.batch.clean`), its
manifest for resuming (:mod:`~mocapfix.batch.manifest`) and ``check``
(:mod:`~mocapfix.batch.check`).
"""
