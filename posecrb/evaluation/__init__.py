"""The evaluation pipeline behind ``bounds``, ``tables`` and ``regress``: one dataset's graph-only
bounds, certified estimate and FIM log-det (``evaluate``), and from those rows Tables I-IV
(``tables``), the paper's printed values (``published``) and the regression against
datasets/expected.json (``regress``)."""
