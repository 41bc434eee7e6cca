"""The paper's experiments: its protocol, the runs' records, the statistics, the claims, the
report, the ablation of our readings and the figures.

Submodules: ``protocol`` (the paper's worlds, systems, trial counts and comparisons, stated
once), ``records`` (what a run writes: systems, configs, results documents), ``stats`` (Tables
3-5, robustness tests, H1-H4), ``claims`` (the paper's 32 claims), ``report``, ``ablation``,
``sweep``, ``seeds`` (the protocol on N fresh LTL seeds, resumable per seed) and ``plotting``.

This layer sits on top of the engine (``jaxais.envs``, ``controllers``, ``loop``,
``systems``, ``trials``, ...); nothing below imports from it. Importing the package (or
``protocol``) does not start JAX.
"""
