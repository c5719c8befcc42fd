"""The generic FMI 2.0 co-simulation master on fmpy (knows nothing of the ABU)."""
