"""The founding paper's own reproduction and the research built on it, loaded on first use:

- :mod:`~granchain.paper.reproduce` and :mod:`~granchain.paper.report`: ``granchain reproduce``, the
  paper's ensembles, figures, data files and report;
- :mod:`~granchain.paper.figures`: one module per figure (``compute()`` and ``plot()``);
- :mod:`~granchain.paper.validity`: where the effective chain and the BCA hold (validity maps);
- :mod:`~granchain.paper.dephasing`: why the averaged pulse decays (dephasing of realisations).

These were ``granchain.figures``, ``granchain.validity`` and ``granchain.dephasing`` before 0.5; those
paths still work and warn (:mod:`granchain._moved`).
"""
