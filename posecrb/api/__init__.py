"""The public library: the functions ``posecrb`` exports, one module per concept.

``graphs``: ``load`` and ``parse``; ``solve``; ``bounds``; ``models``: ``fim`` and ``crlb``;
``select``; ``timeline``. Each takes a graph, a path or a dataset name and keywords named as the
command-line options (snake case, same defaults; timing repeats once), checked once by
``arguments`` (``ArgumentError`` in Python terms), and returns the result its compute package
made (``BoundsResult`` from ``posecrb.models.paper``, ``FimResult`` and ``CrlbResult`` from
``posecrb.models``, ``SolveResult`` from ``posecrb.solver``, ``SelectResult`` from
``posecrb.selection``, ``TimelineResult`` from ``posecrb.incremental``). No function writes a file:
results are written by ``Result.save``, graphs by ``posecrb.io.write_g2o``, figures by
``posecrb.report.plot_*``. ``posecrb/__init__.py`` imports the functions on first use.
"""
