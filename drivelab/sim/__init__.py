"""The simulator layer: worlds as arrays, stepped by compiled kernels (``core/``), signalised
junctions (``junctions/``), roads described as blocks (``roads/``), route tracking (``route``), and
highway-env itself as the reference (``reference/``). It knows no scenario by name: a simulator
reads the ``Scenario`` it is handed (docs/architecture.md)."""
