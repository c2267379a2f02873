"""The public library: the functions ``posecrb`` exports and the two results built here.

``functions``: ``load``, ``parse``, ``solve``, ``bounds``, ``fim``, ``crlb``, ``select``, each
taking a graph, a path or a dataset name, keywords named as the command-line options (snake
case, same defaults; timing repeats once). ``arguments``: the checks of their arguments, raising
``ArgumentError`` in Python terms. ``results``: ``BoundsResult`` and ``SelectResult`` (the other
results come from the layers that compute them: ``SolveResult`` from ``posecrb.solver``,
``FimResult`` and ``CrlbResult`` from ``posecrb.models``). The command line calls these
functions and renders their results; ``posecrb/__init__.py`` imports them on first use.
"""
