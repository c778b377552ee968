"""Road networks described without highway-env: the town's and the circuits' geometry, junction
metadata, lights and crossings, and the rules of the town's traffic (``town_rules``). Both
simulators read them: the compiled core through lane arrays, the highway-env reference through
lane objects built from the same description."""
