"""momentid's benchmarks, kept out of the installed package.

``python -m benchmarks`` times every stage against a raw baseline measured in the same run
(:mod:`benchmarks.bench`); ``python -m benchmarks.scaling``, ``.accuracy``, ``.diagnosis``,
``.diagnosis_variants``, ``.memory`` and ``.reconstruction`` produce the figures and tables in
``docs/``.  Every figure is a ratio or an accuracy, never an absolute time asserted in a test.
"""
