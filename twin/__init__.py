"""The synthetic camera: recordings of known mu rendered from the co-simulation (the report's
experiment) or from the harsh random family (drives, lamps, lens, sensor drawn from a seed).

A leaf above both halves (it simulates with ``harness`` and writes recordings with
``measurement.imaging``): only the command line, the API, tests and benchmarks import it.
"""
