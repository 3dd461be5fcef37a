"""Figures. One module per view (spectrum, stiffness, modes, …); the CLI and the notebooks call
the same functions, which take data and return a matplotlib Figure (no second plotting path)."""
