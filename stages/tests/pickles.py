"""Writes sbert_text_features.pkl the way MesaTask's users have it, for stages/tests/pickle_numpy.rs.

usage: pickles.py OUT_DIR        writes <case>.pkl, <case>.bin (the expected C-order little-endian
                                 bytes), <case>.uids.json, and cases.json listing the cases
       pickles.py --check PKL BIN UIDS   loads PKL with pickle.load (as compress_pickle does for
                                 .pkl) and checks the array equals BIN bit for bit

numpy 2.x names its reconstruction functions `numpy._core.*`; with numpy 1.x installed, those
names are produced by registering the same functions under numpy 2.x's module names.
"""
import json
import pickle
import sys
import types

import numpy as np


def numpy2_names():
    """A reducer_override that names the numpy 2.x globals."""
    fakes = {}
    for module, name in [("numpy._core.multiarray", "_reconstruct"), ("numpy._core.numeric", "_frombuffer")]:
        mod = sys.modules.get(module) or types.ModuleType(module)
        sys.modules[module] = mod

        def fake(*args):  # never called: only its name is written
            raise RuntimeError("not called")

        fake.__module__ = module
        fake.__qualname__ = name
        fake.__name__ = name
        setattr(mod, name, fake)
        fakes[name] = fake

    def override(self, obj):
        if isinstance(obj, np.ndarray):
            rv = obj.__reduce_ex__(self.protocol_number)
            return (fakes[rv[0].__name__],) + tuple(rv[1:])
        return NotImplemented

    return override


def write(out):
    rng = np.random.default_rng(7)
    uids = [f"{i:032x}" for i in range(6)] + ["ünïcode-uid", "u" * 300]
    base = rng.standard_normal((len(uids), 768)).astype(np.float32)
    # Values whose bits a conversion would change: NaN payloads, -0, inf, subnormals.
    base[0, :6] = [np.nan, -0.0, np.inf, -np.inf, 1e-42, 6e-8]
    base.view(np.uint32)[1, 0] = 0x7FC00123
    cases = []
    override2 = numpy2_names()

    class Numpy2Pickler(pickle.Pickler):
        reducer_override = override2

        def __init__(self, f, protocol):
            super().__init__(f, protocol=protocol)
            self.protocol_number = protocol

    for proto in (2, 3, 4, 5):
        for kind in ("f2", "f4"):
            for numpy_major in (1, 2):
                for order in ("C", "F", ">"):
                    arr = base.astype(kind)
                    if kind == "f2":
                        arr.view(np.uint16)[1, 1] = 0x7E05  # a float16 NaN payload
                    expected = np.ascontiguousarray(arr).astype("<" + kind).tobytes()
                    if order == "F":
                        arr = np.asfortranarray(arr)
                    elif order == ">":
                        arr = arr.astype(">" + kind)
                    name = f"p{proto}_{kind}_np{numpy_major}_{'be' if order == '>' else order}"
                    with open(f"{out}/{name}.pkl", "wb") as f:
                        cls = Numpy2Pickler if numpy_major == 2 else pickle.Pickler
                        p = cls(f, protocol=proto)
                        p.dump({"uids": uids, "text_features": arr})
                    with open(f"{out}/{name}.bin", "wb") as f:
                        f.write(expected)
                    with open(f"{out}/{name}.uids.json", "w") as f:
                        json.dump(uids, f)
                    cases.append({"name": name, "kind": kind, "numpy": numpy_major, "proto": proto})
    with open(f"{out}/cases.json", "w") as f:
        json.dump(cases, f)


def check(pkl, bin_path, uids_path):
    with open(pkl, "rb") as f:
        d = pickle.load(f)
    with open(bin_path, "rb") as f:
        expected = f.read()
    with open(uids_path) as f:
        uids = json.load(f)
    arr = d["text_features"]
    assert isinstance(arr, np.ndarray), type(arr)
    assert d["uids"] == uids, "uids differ"
    assert arr.shape == (len(uids), len(expected) // len(uids) // arr.dtype.itemsize), arr.shape
    assert np.ascontiguousarray(arr).astype("<" + arr.dtype.str[1:]).tobytes() == expected, "bytes differ"
    print("ok", arr.dtype, arr.shape)


if __name__ == "__main__":
    if sys.argv[1] == "--check":
        check(*sys.argv[2:5])
    else:
        write(sys.argv[1])
