"""Roads described without highway-env: the block vocabulary (straights, arcs, junctions) and the
grids and circuits built from it, the ``RoadDescription`` lanes they give, ``RoadMap`` arrays for
sensors and drawings, and the same description as a highway-env network for the reference."""
