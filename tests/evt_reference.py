"""Prophesee EVT 3.0 written and read straight from the format description, for tests only.

Independent of faery (which pecs uses): the decoder follows the word table of the EVT 3.0
specification (OpenEB docs), the encoder writes what a camera writes, including vector words
(VECT_BASE_X + VECT_12 / VECT_8), trigger and OTHERS words, and TIME_HIGH wrapping every 2^24 µs.
"""

from __future__ import annotations

import numpy as np

ADDR_Y, ADDR_X, VECT_BASE_X, VECT_12, VECT_8 = 0x0, 0x2, 0x3, 0x4, 0x5
TIME_LOW, TIME_HIGH, EXT_TRIGGER, OTHERS = 0x6, 0x8, 0xA, 0xE


def header(width: int, height: int) -> bytes:
    return f"% evt 3.0\n% format EVT3;height={height};width={width}\n% end\n".encode()


def decode(data: bytes) -> dict[str, np.ndarray]:
    """Vectorised EVT3 decoder: forward-fill the state words, expand the vector masks."""
    start = 0
    while data.startswith(b"%", start):
        start = data.index(b"\n", start) + 1
    words = np.frombuffer(data, dtype="<u2", offset=start)
    kind, value = words >> 12, (words & 0xFFF).astype(np.int64)
    index = np.arange(len(words))

    def last(mask: np.ndarray, values: np.ndarray) -> np.ndarray:
        """For every word, `values` at the latest word (at or before it) where `mask` holds."""
        where = np.flatnonzero(mask)
        if len(where) == 0:
            return np.zeros(len(index), dtype=np.int64)
        pos = np.searchsorted(where, index, side="right") - 1
        out = values[where][np.maximum(pos, 0)]
        return np.where(pos >= 0, out, 0)

    # 24-bit time: TIME_HIGH counts 4096 µs, wrapping at 2^12; count the wraps.
    is_high = kind == TIME_HIGH
    high = value[is_high]
    wraps = np.concatenate([[0], np.cumsum(np.diff(high) < 0)])
    high_full = np.zeros(len(words), dtype=np.int64)
    high_full[is_high] = high + 4096 * wraps
    t = (last(is_high, high_full) << 12) | last(kind == TIME_LOW, value)
    y = last(kind == ADDR_Y, value & 0x7FF)

    # Single events.
    single = kind == ADDR_X
    events = [
        (
            index[single],
            np.zeros(int(single.sum()), np.int64),
            t[single],
            value[single] & 0x7FF,
            y[single],
            value[single] >> 11,
        )
    ]
    # Vectors: base x (and polarity) from VECT_BASE_X, advanced by 12 or 8 after each vector word.
    is_base = kind == VECT_BASE_X
    step = np.where(kind == VECT_12, 12, np.where(kind == VECT_8, 8, 0))
    advanced = np.cumsum(step) - step  # steps before this word
    base = last(is_base, (value & 0x7FF) - advanced) + advanced
    polarity = last(is_base, value >> 11)
    for bits, vector_kind in ((12, VECT_12), (8, VECT_8)):
        rows = np.flatnonzero(kind == vector_kind)
        for k in range(bits):
            hit = rows[(value[rows] >> k) & 1 == 1]
            events.append((hit, np.full(len(hit), k), t[hit], base[hit] + k, y[hit], polarity[hit]))
    word, order_k, t_all, x_all, y_all, p_all = (
        np.concatenate(c) for c in zip(*events, strict=True)
    )
    order = np.lexsort((order_k, word))
    return {"t": t_all[order], "x": x_all[order], "y": y_all[order], "p": p_all[order]}


def encode(t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray) -> bytes:
    """Camera-style EVT3 words: runs of neighbouring x (same t, y, p) become vector words."""
    words: list[int] = []
    last_high = last_low = last_y = None
    i = 0
    while i < len(t):
        high, low = int(t[i]) >> 12, int(t[i]) & 0xFFF
        if high != last_high:
            # Sensors emit every TIME_HIGH step (each 4096 µs), with or without events.
            first = high if last_high is None else last_high + 1
            words.extend(TIME_HIGH << 12 | (step & 0xFFF) for step in range(first, high + 1))
            last_high, last_low = high, None
        if low != last_low:
            words.append(TIME_LOW << 12 | low)
            last_low = low
        if y[i] != last_y:
            words.append(ADDR_Y << 12 | int(y[i]))
            last_y = y[i]
        run = 1
        while (
            i + run < len(t)
            and run < 12
            and t[i + run] == t[i]
            and y[i + run] == y[i]
            and p[i + run] == p[i]
            and x[i + run] == x[i] + run
        ):
            run += 1
        if run >= 3:
            words.append(VECT_BASE_X << 12 | int(p[i]) << 11 | int(x[i]))
            words.append((VECT_12 if run > 8 else VECT_8) << 12 | ((1 << run) - 1))
        else:
            run = 1
            words.append(ADDR_X << 12 | int(p[i]) << 11 | int(x[i]))
        i += run
        if i % 97 == 0:  # cameras interleave trigger and housekeeping words
            words.extend([EXT_TRIGGER << 12 | 1, OTHERS << 12 | 0x123])
    return np.asarray(words, dtype="<u2").tobytes()
