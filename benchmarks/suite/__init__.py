"""posecrb's in-process benchmarks: an airspeed velocity (asv) suite of the public library.

Every benchmark calls a name of ``posecrb.__all__`` on an input of ``inputs.py`` (the SE-Sync
datasets and noisy grids): ``time_*`` the wall time of one call, ``peakmem_*`` the process's peak
resident memory over it. Configuration: ``benchmarks/asv.conf.json``; ``make bench`` and ``make
bench-quick`` run it, ``benchmarks/report.py`` turns its results into tables.
"""
