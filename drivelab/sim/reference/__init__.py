"""highway-env itself as a backend (``backend="highway"``): the reference the compiled core is
tested against, one world at a time (``per_world`` holds K of them)."""
