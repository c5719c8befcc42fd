"""Imaging: recordings (frames) -> the three marker tracks [px]; the camera lens."""
