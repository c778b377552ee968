"""drivelab.isa: the pinned instruction set that shipped agents' checks are recorded and compared
under, and scripts/like_avx2.sh, which runs a command with the same pins."""

import re
from pathlib import Path

import pytest

from drivelab.isa import PINNED_ISA, call_pinned, code_paths

SCRIPT = Path(__file__).parents[1] / "scripts" / "like_avx2.sh"
THREADS = {"OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"}


def test_the_script_sets_the_pins_of_drivelab_isa():
    exports = dict(re.findall(r"^export (\w+)=\"?([^\"\n]*)\"?$", SCRIPT.read_text(), re.MULTILINE))
    assert exports == {key: value for key, value in PINNED_ISA.items() if key not in THREADS}


def test_a_pinned_process_runs_avx2_code_paths_on_one_thread():
    paths = call_pinned("drivelab.isa:code_paths")
    assert paths == {"numpy": "X86_V3", "torch": "AVX2", "numba": "haswell"}
    assert call_pinned("os:getenv", "ONEDNN_MAX_CPU_ISA") == "AVX2"
    assert call_pinned("torch:get_num_threads") == 1
    # this process is not pinned: it names its own (on an AVX2 machine the same, but numba's CPU)
    assert set(code_paths()) == set(paths)


def test_a_failing_call_raises_with_the_childs_error():
    with pytest.raises(RuntimeError, match=r"exited 1:(.|\n)*No module named 'no_such_module'"):
        call_pinned("no_such_module:f")
