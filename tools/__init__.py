"""The project's tools: the demo, the benchmark and its sections, the mutation check, the bag
recorder and the FDCHP comparisons. Run one from the repository's root as a module,
``python -m tools.bench``; ``make venv`` also puts the root on the venv's path, so
``.venv/bin/python tools/bench.py`` works from anywhere."""
