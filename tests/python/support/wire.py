"""brickserver's answers on the wire: the framing of its binary answers, the boxes its region
answers cover, and its metrics."""

import json
import struct


def unframe(body, magic):
    """Splits a framed binary answer (8-byte `magic`, little-endian u32 header length, JSON
    header, payload) into (header, payload)."""
    assert body[:8] == magic
    (n,) = struct.unpack("<I", body[8:12])
    return json.loads(body[12 : 12 + n]), body[12 + n :]


def widen(lo, hi, step, size):
    """[lo, hi) widened to multiples of `step`, clipped to `size` (per axis, x, y, z)."""
    return [l // s * s for l, s in zip(lo, step)], [min(-(-h // s) * s, n) for h, s, n in zip(hi, step, size)]


def metric(text, name):
    """The value of the sample `name` (with labels, as written) in OpenMetrics text."""
    for line in text.splitlines():
        if line.startswith(name + " "):
            return float(line.split()[-1])
    raise AssertionError(f"{name} not in metrics:\n{text}")
