"""What the independent-master scripts (`*_drive.py`) share: the result record, the checks, and
CiA 301 PDO mapping arithmetic (entries index, sub, bits packed from bit 0, little-endian)."""

import struct

# The script's result, printed as `<MASTER>_RESULT {json}` at its end.
RESULT = {"ok": False, "steps": []}
FMT = {8: "b", 16: "h", 32: "i"}


class CheckFailed(Exception):
    pass


def check(cond, what):
    if not cond:
        raise CheckFailed(what)


def step(name, **kw):
    RESULT["steps"].append(dict(step=name, **kw))


def layout(entries):
    """{index: (byte offset, bits)} of a mapping (the first entry of each object; gaps, index
    0, take their bits but no name)."""
    out, bit = {}, 0
    for i, s, n in entries:
        if i != 0 and i not in out:
            out[i] = (bit // 8, n)
        bit += n
    return out


def get(buf, lay, index, signed=True):
    o, n = lay[index]
    f = FMT[n]
    return struct.unpack_from("<" + (f if signed else f.upper()), buf, o)[0]


def put(buf, lay, index, value):
    o, n = lay[index]
    struct.pack_into("<" + FMT[n].upper(), buf, o, value & ((1 << n) - 1))
