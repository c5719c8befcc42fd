"""Report: the measurement's summary text, JSON, figures, and several records combined."""
