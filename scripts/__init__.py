"""The command-line entry points, installed as ``jaxais.scripts`` (pyproject's package-dir).

Each parses its flags, calls one library function (:mod:`jaxais.experiments`, ...) and prints a
line; :mod:`jaxais.cli` turns mistakes and signals into one line on stderr and an exit status.
Run one as ``python scripts/NAME.py``, ``python -m jaxais.scripts.NAME`` or, for those pyproject
lists, as the console script ``jaxais-NAME``.
"""
