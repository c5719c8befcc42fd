"""The report's experiments on the FMUs: staircase, ramp, Table 4.1, sweeps, their files."""
