"""momentid's benchmarks: ``python -m benchmarks`` (the same as ``momentid bench``).

The stage benchmarks live in :mod:`momentid.bench` so that an installed
``momentid bench`` runs them too; ``python -m benchmarks.scaling`` draws the
scaling figures of the README's Performance section.
"""
