"""Signalised junctions, shared by the town and the block maps: the light cycle and the rules
(``rules``), the lane metadata of junctions and crossings as arrays (``arrays``), pedestrians and
lights as kernels (``pedestrians``), vehicles that drive routes through junctions (``traffic``),
and the row layouts they share (``rows``)."""
