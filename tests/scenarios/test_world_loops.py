"""The town's and the block maps' world loops: a serial and a parallel variant, each cached apart."""

import pytest

from drivelab.scenarios.blocks import simulator as blocks
from drivelab.scenarios.town import simulator as town


@pytest.mark.parametrize("module", [town, blocks], ids=["town", "blocks"])
def test_the_serial_and_parallel_loops_have_cache_entries_of_their_own(module):
    # numba's cache key holds a function's name and code, not parallel=: under one name, the
    # variant compiled second would load the first one's machine code
    serial, parallel = module._SERIAL, module._PARALLEL
    assert not serial.targetoptions["parallel"] and parallel.targetoptions["parallel"]
    assert serial._cache._cache_file._index_name != parallel._cache._cache_file._index_name
