"""Experiment planning: identify the speed loop, design a staircase, propose the next run."""
