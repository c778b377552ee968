"""The compiled core: vehicle rows and lane tables, highway-env's IDM and MOBIL traffic as numba
kernels over K worlds, the episode set-up helpers every scenario's spawn hook uses, PCG64 in
numba, and ``FastSimulator`` / ``FastBackend``."""
