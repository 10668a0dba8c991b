"""Sweeps and Monte Carlo runs of an experiment on Dask (``robofmu sweep``).

- :mod:`.design`: what is varied and the list of runs;
- :mod:`.worker`: one run in a worker, returning its record;
- :mod:`.metrics`: the metrics of a record;
- :mod:`.engine`: the Dask cluster, submission, retries, progress;
- :mod:`.journal`: ``sweep.csv`` written as runs finish, and ``sweep.parquet``;
- :mod:`.result`: :class:`~.result.SweepRun`, what a sweep gives back;
- :mod:`.figures` and :mod:`.report`: drawn and written from a SweepRun;
- :mod:`.run`: the checks and flow of ``robofmu sweep`` (its parser: ``robofmu.system.commands.sweep``).
"""
