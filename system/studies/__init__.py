"""Studies: what the demo report shows beyond single runs, each returning typed results.

The accuracy study against a monolithic reference (:mod:`.convergence`, with the in-process
replica of a diagram in :mod:`.replica`), the cross-check of a closed-chain plant against an
independent formulation (:mod:`.crosscheck`), the Newton-Raphson tutorial (:mod:`.newton`), the
workspace and isotropy maps of parallel robots (:mod:`.workspace`), the tables compared with the
seed documents (:mod:`.tables`) and the flagship demo that runs them all (:mod:`.demo`, its plan
``demo.toml`` read by :mod:`.plan`). The data
they read (``demo.toml``, the seeds' tables) lives beside them. Imports the core, ``sweep``,
``stepresponse`` and ``interop``; nothing outside ``studies`` and the CLI imports a study.
"""
