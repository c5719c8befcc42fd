"""The identified PI speed loop of the experimental setup and its staircase reference.

Only relative imports (and abu_model through a guarded import) so the package can be
vendored into an FMU under another name.
"""
