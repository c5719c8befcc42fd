"""Kinematics: marker tracks -> theta, beta, omega, omega_dot with error bars; beta's lighting harmonics."""
