"""numpy's PCG64 generator as plain uint64 arrays, so that compiled code can seed and draw from
many of them in one call.

A generator is a ``(6,)`` uint64 array: the 128-bit LCG state and increment as (high, low)
words, then numpy's 32-bit buffer (a flag and the buffered half of the last 64-bit output).
``seeded_states`` builds them from integer seeds as ``gymnasium.utils.seeding.np_random``
(``PCG64(SeedSequence(seed))``) does; ``next_uint64``, ``bounded_int`` and ``uniform`` return the
numbers ``Generator.random_raw`` / ``integers(0, n)`` / ``uniform(a, b)`` would, in the same order
(PCG's XSL-RR output over a 128-bit LCG, O'Neill 2014; Lemire's bounded integers).
"""

from __future__ import annotations

import numpy as np
from numba import njit

STATE_HI, STATE_LO, INC_HI, INC_LO, HAS_UINT32, UINTEGER = range(6)
MULT_HI, MULT_LO = np.uint64(2549297995355413924), np.uint64(4865540595714422341)  # PCG's 128-bit multiplier
_MASK32 = np.uint64(0xFFFFFFFF)
_ONE, _ZERO = np.uint64(1), np.uint64(0)
_32, _63, _64_MINUS = np.uint64(32), np.uint64(63), np.uint64(64)
_DOUBLE_UNIT = 1.0 / 9007199254740992.0  # 2**-53


def seeded_states(seeds) -> np.ndarray:
    """(M, 6) generator states, row m as ``PCG64(SeedSequence(seeds[m]))`` starts (seeds >= 0,
    below 2**63)."""
    seeds = np.atleast_1d(np.asarray(seeds, dtype=np.int64))
    if seeds.size and seeds.min() < 0:
        raise ValueError("PCG64 seeds must be >= 0")
    return _seeded_states(seeds)


# SeedSequence's constants: a pool of 4 uint32 words, the hash multipliers and the xor-shift
POOL_SIZE = 4
INIT_A, MULT_A, INIT_B, MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED
MIX_MULT_L, MIX_MULT_R, XSHIFT = 0xCA01F9DD, 0x4973F715, 16


@njit(cache=True)
def _seed_words(seed: int) -> np.ndarray:
    """SeedSequence's entropy words of a non-negative int: its 32-bit chunks, low first ([0] for 0)."""
    words = np.zeros(2, dtype=np.uint64)
    count = 0
    value = np.uint64(seed)
    while True:
        words[count] = value & _MASK32
        count += 1
        value = value >> _32
        if value == _ZERO:
            return words[:count]


@njit(cache=True)
def _hashmix(value: np.uint64, hash_const: np.ndarray, mult: int = MULT_A) -> np.uint64:
    value = (value ^ hash_const[0]) & _MASK32
    hash_const[0] = (hash_const[0] * np.uint64(mult)) & _MASK32
    value = (value * hash_const[0]) & _MASK32
    return value ^ (value >> np.uint64(XSHIFT))


@njit(cache=True)
def _mix(x: np.uint64, y: np.uint64) -> np.uint64:
    result = (np.uint64(MIX_MULT_L) * x - np.uint64(MIX_MULT_R) * y) & _MASK32
    return result ^ (result >> np.uint64(XSHIFT))


@njit(cache=True)
def _seed_sequence_state(seed: int) -> np.ndarray:
    """``SeedSequence(seed).generate_state(4, np.uint64)``: the entropy mixed into the pool, then
    8 hashed 32-bit words paired low-first into 4 uint64."""
    entropy = _seed_words(seed)
    hash_const = np.array([INIT_A], dtype=np.uint64)
    pool = np.zeros(POOL_SIZE, dtype=np.uint64)
    for i in range(POOL_SIZE):
        pool[i] = _hashmix(entropy[i] if i < entropy.size else _ZERO, hash_const)
    for source in range(POOL_SIZE):
        for target in range(POOL_SIZE):
            if source != target:
                pool[target] = _mix(pool[target], _hashmix(pool[source], hash_const))
    for source in range(POOL_SIZE, entropy.size):
        for target in range(POOL_SIZE):
            pool[target] = _mix(pool[target], _hashmix(entropy[source], hash_const))
    hash_const[0] = np.uint64(INIT_B)
    words = np.zeros(8, dtype=np.uint64)
    for i in range(8):
        words[i] = _hashmix(pool[i % POOL_SIZE], hash_const, MULT_B)
    out = np.zeros(4, dtype=np.uint64)
    for j in range(4):
        out[j] = words[2 * j] | (words[2 * j + 1] << _32)
    return out


@njit(cache=True)
def _seeded_states(seeds: np.ndarray) -> np.ndarray:
    states = np.zeros((seeds.size, 6), dtype=np.uint64)
    for m in range(seeds.size):
        words = _seed_sequence_state(seeds[m])
        _set_seed(states[m], words[0], words[1], words[2], words[3])
    return states


@njit(cache=True, inline="always")
def _mul_64(a: np.uint64, b: np.uint64) -> tuple[np.uint64, np.uint64]:
    """The 128-bit product of two uint64 as (high, low)."""
    a_lo, a_hi = a & _MASK32, a >> _32
    b_lo, b_hi = b & _MASK32, b >> _32
    lo_lo = a_lo * b_lo
    hi_lo = a_hi * b_lo
    lo_hi = a_lo * b_hi
    hi_hi = a_hi * b_hi
    cross = (lo_lo >> _32) + (hi_lo & _MASK32) + lo_hi
    high = hi_hi + (hi_lo >> _32) + (cross >> _32)
    low = (cross << _32) | (lo_lo & _MASK32)
    return high, low


@njit(cache=True, inline="always")
def _step(state: np.ndarray) -> None:
    """state = state * MULT + inc (mod 2**128)."""
    high, low = _mul_64(state[STATE_LO], MULT_LO)
    high = high + state[STATE_HI] * MULT_LO + state[STATE_LO] * MULT_HI
    low_sum = low + state[INC_LO]
    carry = _ONE if low_sum < low else _ZERO
    state[STATE_HI] = high + state[INC_HI] + carry
    state[STATE_LO] = low_sum


@njit(cache=True)
def _set_seed(state: np.ndarray, seed_hi, seed_lo, inc_hi, inc_lo) -> None:
    """pcg64_set_seed: inc = (initseq << 1) | 1; step; state += initstate; step."""
    state[INC_HI] = (np.uint64(inc_hi) << _ONE) | (np.uint64(inc_lo) >> _63)
    state[INC_LO] = (np.uint64(inc_lo) << _ONE) | _ONE
    state[STATE_HI], state[STATE_LO] = _ZERO, _ZERO
    _step(state)
    low = state[STATE_LO] + np.uint64(seed_lo)
    carry = _ONE if low < state[STATE_LO] else _ZERO
    state[STATE_HI] = state[STATE_HI] + np.uint64(seed_hi) + carry
    state[STATE_LO] = low
    _step(state)
    state[HAS_UINT32], state[UINTEGER] = _ZERO, _ZERO


@njit(cache=True)
def next_uint64(state: np.ndarray) -> np.uint64:
    """The next 64-bit output (``random_raw``): step, then XSL-RR of the new state."""
    _step(state)
    xored = state[STATE_HI] ^ state[STATE_LO]
    rotation = state[STATE_HI] >> np.uint64(58)
    return (xored >> rotation) | (xored << ((_64_MINUS - rotation) & _63))


@njit(cache=True)
def next_uint32(state: np.ndarray) -> np.uint64:
    """numpy's buffered 32-bit draw: the low half of a 64-bit output, its high half next time."""
    if state[HAS_UINT32] != _ZERO:
        state[HAS_UINT32] = _ZERO
        return state[UINTEGER]
    value = next_uint64(state)
    state[HAS_UINT32], state[UINTEGER] = _ONE, value >> _32
    return value & _MASK32


@njit(cache=True)
def bounded_int(state: np.ndarray, n: int) -> int:
    """``Generator.integers(0, n)`` for 1 <= n <= 2**32 - 1 (Lemire's method, 32-bit draws)."""
    if n == 1:
        return np.int64(0)  # numpy draws nothing for a single value
    rng = np.uint64(n - 1)
    excl = rng + _ONE
    m = next_uint32(state) * excl
    leftover = m & _MASK32
    if leftover < excl:
        threshold = (_MASK32 - rng) % excl
        while leftover < threshold:
            m = next_uint32(state) * excl
            leftover = m & _MASK32
    return np.int64(m >> _32)


@njit(cache=True)
def uniform(state: np.ndarray, low: float, high: float) -> float:
    """``Generator.uniform(low, high)``: low + (high - low) * a 53-bit double."""
    return low + (high - low) * (float(next_uint64(state) >> np.uint64(11)) * _DOUBLE_UNIT)


def state_of(generator: np.random.Generator) -> np.ndarray:
    """(6,) words of a numpy ``Generator`` on PCG64, so that compiled code draws what it would next."""
    state = generator.bit_generator.state
    if state["bit_generator"] != "PCG64":
        raise ValueError(f"expected a PCG64 generator, got {state['bit_generator']}")
    words = np.zeros(6, dtype=np.uint64)
    mask = (1 << 64) - 1
    words[STATE_HI], words[STATE_LO] = state["state"]["state"] >> 64, state["state"]["state"] & mask
    words[INC_HI], words[INC_LO] = state["state"]["inc"] >> 64, state["state"]["inc"] & mask
    words[HAS_UINT32], words[UINTEGER] = state["has_uint32"], state["uinteger"]
    return words


def set_state(generator: np.random.Generator, words: np.ndarray) -> None:
    """Put ``words`` (6,) into a numpy ``Generator`` on PCG64: it then draws what compiled code would."""
    generator.bit_generator.state = {
        "bit_generator": "PCG64",
        "state": {
            "state": (int(words[STATE_HI]) << 64) | int(words[STATE_LO]),
            "inc": (int(words[INC_HI]) << 64) | int(words[INC_LO]),
        },
        "has_uint32": int(words[HAS_UINT32]),
        "uinteger": int(words[UINTEGER]),
    }


@njit(cache=True)
def standard_exponential_inv(state: np.ndarray) -> float:
    """``Generator.standard_exponential(method="inv")``: ``-log1p(-U)`` of the next 53-bit double U
    (numpy 2's ``random_standard_exponential_inv_fill``; ``-log(1 - U)``, numpy 1's form, differs in
    the last bit for about 7 % of draws). The 32-bit buffer is left as it is."""
    return -np.log1p(-(float(next_uint64(state) >> np.uint64(11)) * _DOUBLE_UNIT))
