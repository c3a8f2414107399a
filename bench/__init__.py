"""siteline's benchmarks. Run one from the repository root as ``python -m bench.<name>`` (``make bench``
runs them all); each prints its figures beside a baseline measured in the same run."""
