"""Device memory shared by several RLAD processes on one GPU (memory.py), on the CPU: the device's
free memory is a fake, processes are ledgers with other pids, or real forked processes."""

import gc
import math
import multiprocessing
import types

import numpy as np
import pytest

from drivelab.agents.rlad import sac
from drivelab.agents.rlad.memory import LEDGER_ENV, DeviceMemoryLedger, pid_alive
from drivelab.agents.rlad.replay import FrameReplayBuffer
from tests.agents.test_rlad import _agent

GIB = 2**30


def test_a_second_process_does_not_take_frames_that_only_fit_once(tmp_path):
    live = {101, 102, 103}
    path = tmp_path / "ledger.json"
    first, second = (DeviceMemoryLedger(path, pid, alive=live.__contains__) for pid in (101, 102))
    free = 100 * GIB  # nothing allocated yet: both read the same free memory
    token = first.reserve("gpu-a", 40 * GIB, lambda: free)
    assert token is not None  # 40 < 100 / 2
    assert second.reserve("gpu-a", 40 * GIB, lambda: free) is None  # 40 >= (100 - 40 pending) / 2
    assert second.reserve("gpu-b", 40 * GIB, lambda: free) is not None  # another device: its own memory
    assert second.reserve("gpu-a", 20 * GIB, lambda: free) is not None  # 20 < (100 - 40) / 2
    # once the first process has allocated, its bytes are out of the free memory, not pending
    first.allocated(token)
    free -= 40 * GIB
    third = DeviceMemoryLedger(path, 103, alive=live.__contains__)
    assert third.reserve("gpu-a", 21 * GIB, lambda: free) is None  # (60 free − 20 pending) / 2 = 20
    assert third.reserve("gpu-a", 14 * GIB, lambda: free) is not None  # (not 0: 40 counted twice)
    assert [e["allocated"] for e in first.entries() if e["pid"] == 101] == [True]
    # a killed process: its reservation is ignored and dropped
    live.discard(101)
    free += 40 * GIB
    assert third.reserve("gpu-a", 30 * GIB, lambda: free) is not None  # (100 − 20 − 14) / 2 = 33
    assert {e["pid"] for e in second.entries()} == {102, 103}
    # a released reservation is gone
    for entry in second.entries():
        if entry["pid"] == 102:
            second.release(entry["token"])
    assert {e["pid"] for e in second.entries()} == {103}


def _ask(path, barrier, results):
    barrier.wait()  # both processes reserve at the same moment
    token = DeviceMemoryLedger(path).reserve("gpu-a", 40 * GIB, lambda: 100 * GIB)
    results.put(token is not None)


def test_two_processes_asking_at_once_do_not_both_take_the_device(tmp_path):
    context = multiprocessing.get_context("fork")
    barrier, results = context.Barrier(2), context.Queue()
    workers = [
        context.Process(target=_ask, args=(tmp_path / "ledger.json", barrier, results)) for _ in range(2)
    ]
    for worker in workers:
        worker.start()
    taken = sorted(results.get(timeout=60) for _ in workers)
    for worker in workers:
        worker.join(timeout=60)
    assert taken == [False, True]
    # both have exited: their reservations no longer count
    assert DeviceMemoryLedger(tmp_path / "ledger.json").entries() == []


def test_pid_alive():
    assert pid_alive(multiprocessing.current_process().pid)
    process = multiprocessing.get_context("fork").Process(target=int)
    process.start()
    process.join()
    assert not pid_alive(process.pid)


@pytest.mark.parametrize("through", ["first write", "loaded replay"])
def test_the_replay_reports_when_it_allocates_its_device_frames(through):
    calls = []
    replay = FrameReplayBuffer(8, (3, 4, 4), 3, (10, 2), 6, 2, frame_device="cpu")
    replay.on_allocate = lambda: calls.append(1)
    frame = np.zeros((3, 4, 4), np.uint8)
    if through == "first write":
        replay.start_episode(frame, np.zeros((10, 2)), np.zeros(6), 0)
        replay.add(np.zeros(2), 0.0, False, frame, np.zeros((10, 2)), np.zeros(6), 0)
    else:  # a checkpointed replay with frames in it
        saved = FrameReplayBuffer(8, (3, 4, 4), 3, (10, 2), 6, 2)
        saved.start_episode(frame, np.zeros((10, 2)), np.zeros(6), 0)
        replay.load_state_arrays(saved.state_arrays())
    assert calls == [1]


def test_agents_reserve_their_device_frames_through_the_ledger(tmp_path, monkeypatch):
    """``replay_frames=auto`` on a (faked) GPU: the second agent finds the first's frames reserved;
    a collected agent's reservation is released."""
    monkeypatch.setenv(LEDGER_ENV, str(tmp_path / "ledger.json"))
    frame_shape = (3, 44, 44)
    nbytes = int((64 * 1.05 + 1) * math.prod(frame_shape))  # the replay's records (buffer_size 64)
    monkeypatch.setattr(sac, "cuda_free_bytes", lambda device: 3 * nbytes)
    monkeypatch.setattr(sac, "device_key", lambda device: "gpu-a")
    gpu = types.SimpleNamespace(type="cuda")

    def on_gpu():
        agent = _agent()
        agent.device = gpu
        return agent, agent._frame_device(frame_shape)

    first, where = on_gpu()
    assert where is gpu  # n < 3n / 2
    assert [e["bytes"] for e in DeviceMemoryLedger().entries()] == [nbytes]
    second, where = on_gpu()
    assert where is None  # n >= (3n − n pending) / 2
    first._frames_allocated()
    assert DeviceMemoryLedger().entries()[0]["allocated"] is True
    del first
    gc.collect()
    assert DeviceMemoryLedger().entries() == []
    assert second._frame_device(frame_shape) is gpu  # deciding again (a loaded replay) finds room
    assert len(DeviceMemoryLedger().entries()) == 1
