"""The random numbers of every run: the Philox-4x64-10 reference (numpy).


Randomness (docs/model.md, "Time and randomness"). Draw ``n`` of purpose ``s`` of
component ``c`` in run ``(seed, scenario_key, cell, replicate)`` takes its
uniforms from the Philox-4×64-10 counter-based generator (Salmon et al.,
"Parallel random numbers: as easy as 1, 2, 3", SC'11; ``numpy.random.Philox``)
with key ``(seed, scenario_key·2³² + c·2¹⁶ + s)`` and counters
``(j, n, cell, replicate)``, j = 0, 1, ... the block of four 64-bit words
within the draw. A uniform is ``(word >> 11)·2⁻⁵³`` as numpy makes it; a
standard normal takes two consecutive uniforms ``(u₁, u₂)`` by one
Box-Muller branch, ``sqrt(−2 ln(1 − u₁)) cos(2π u₂)``. The C runtime
(``fmus/c``) implements the same; :func:`uniforms` and :func:`normals` are
the reference the tests pin it against. A run's numbers therefore do not

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

_MASK64 = (1 << 64) - 1


def philox_key(seed: int, scenario_key: int, component: int, purpose: int) -> tuple[int, int]:
    """Philox key of a stream: ``(seed, scenario_key·2³² + component·2¹⁶ + purpose)``."""
    return int(seed) & _MASK64, ((int(scenario_key) << 32) | (int(component) << 16) | int(purpose)) & _MASK64


def philox_words(key: tuple[int, int], counter: Sequence[int]) -> np.ndarray:
    """The four 64-bit words of Philox-4×64-10 at ``counter`` (numpy's ``Philox`` bit generator).

    numpy advances the counter before it ciphers, so its state is set one
    below ``counter``.
    """
    value = sum((int(c) & _MASK64) << (64 * i) for i, c in enumerate(counter))
    value = (value - 1) % (1 << 256)
    before = np.array([(value >> (64 * i)) & _MASK64 for i in range(4)], dtype=np.uint64)
    gen = np.random.Philox(counter=before, key=np.array(key, dtype=np.uint64))
    return gen.random_raw(4)


def uniforms(seed: int, scenario_key: int, cell: int, replicate: int, component: int, purpose: int,
             draw: int, count: int) -> np.ndarray:
    """The uniforms on [0, 1) of one draw of a stream (module docstring, "Randomness").

    Returns
    -------
    ndarray, shape (count,)
    """
    key = philox_key(seed, scenario_key, component, purpose)
    blocks = [philox_words(key, (j, draw, cell, replicate)) for j in range((count + 3) // 4)]
    words = np.concatenate(blocks)[:count] if blocks else np.zeros(0, dtype=np.uint64)
    return (words >> np.uint64(11)).astype(float) * (1.0 / 9007199254740992.0)


def normals(seed: int, scenario_key: int, cell: int, replicate: int, component: int, purpose: int,
            draw: int, count: int) -> np.ndarray:
    """The standard normals of one draw: Box-Muller on consecutive uniform pairs.

    Uses :mod:`math` (the C library's ``log``, ``sqrt`` and ``cos``), as the C runtime does.
    """
    u = uniforms(seed, scenario_key, cell, replicate, component, purpose, draw, 2 * count)
    return np.array([math.sqrt(-2.0 * math.log(1.0 - u[2 * i])) * math.cos(2.0 * math.pi * u[2 * i + 1])
                     for i in range(count)])


__all__ = ["normals", "philox_key", "philox_words", "uniforms"]
