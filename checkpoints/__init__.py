"""Shipped LTL seeds (installed as ``jaxais.checkpoints``); ``default/`` is the STL's default."""
