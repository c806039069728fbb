"""Ensembles: studies, sampling designs, batch evaluation, the chunked run and its storage.

- :mod:`~skidmc.ensemble.study`: study files (TOML) -> a validated :class:`Study`.
- :mod:`~skidmc.ensemble.sampling`: seeded designs (mc, lhs, sobol, saltelli) and the copula.
- :mod:`~skidmc.ensemble.evaluate`: in-process evaluation of a batch of scenes.
- :mod:`~skidmc.ensemble.executors`: in process, local worker processes, dask.
- :mod:`~skidmc.ensemble.schedule`: time-sized chunks and crash retry.
- :mod:`~skidmc.ensemble.batch`: :func:`evaluate_batch`, the API for adaptive methods.
- :mod:`~skidmc.ensemble.run`: :func:`run_study` (``skidmc run``).
- :mod:`~skidmc.ensemble.storage`: the resumable HDF5 result file.

Nothing is imported here: a worker process imports only what it evaluates with.
"""

__all__: list[str] = []
