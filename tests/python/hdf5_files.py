"""HDF5 files written by h5py for tests/hdf5_io.rs, as the field's tools write them, and the
reading back of meshdeco's SPLOCS-layout export. Prints one JSON line.

Usage:
  python hdf5_files.py write FRAMES.npy FACES.npy DIR
      DIR/frames32.npy: the frames as float32 (what both HDF5 files hold);
      DIR/splocs.h5: `verts` F×N×3 float32 gzip + `tris` (the SPLOCS reference's import script);
      DIR/dfaust.h5: `50002_jumping_jacks` N×3×F float32, chunked, gzip, shuffle, no faces
      (DFAUST's registrations), beside a second sequence `50002_punching`;
      DIR/bad_*.h5: a missing dataset, rank 2, a NaN, a truncated file, a 10^9-frame header
      (chunked, never written), a 10^9-frame contiguous dataset never written, a chunked
      dataset whose second half was never written, integer verts.
  python hdf5_files.py read-export M.h5
      the datasets of meshdeco's export: names, shapes, dtypes and values (lists).
"""
import json
import os
import sys

import h5py
import numpy as np


def write(frames_path, faces_path, out):
    frames = np.load(frames_path).astype(np.float32)
    faces = np.load(faces_path)
    np.save(os.path.join(out, "frames32.npy"), frames)
    with h5py.File(os.path.join(out, "splocs.h5"), "w") as f:
        f.create_dataset("verts", data=frames, compression="gzip")
        f["tris"] = faces
        f.attrs["mean"] = frames.mean(axis=(0, 1))
        f.attrs["scale"] = 1.0
    dfaust = np.ascontiguousarray(frames.transpose(1, 2, 0))  # N × 3 × F
    with h5py.File(os.path.join(out, "dfaust.h5"), "w") as f:
        f.create_dataset("50002_jumping_jacks", data=dfaust, chunks=True, compression="gzip", shuffle=True)
        f.create_dataset("50002_punching", data=dfaust[:, :, ::-1], chunks=True, compression="gzip")
    n = frames.shape[1]
    with h5py.File(os.path.join(out, "bad_missing.h5"), "w") as f:
        f["vertices"] = frames
        f["tris"] = faces
    with h5py.File(os.path.join(out, "bad_rank.h5"), "w") as f:
        f["verts"] = frames.reshape(frames.shape[0], -1)
        f["tris"] = faces
    nan = frames.copy()
    nan[2, 5, 1] = np.nan
    with h5py.File(os.path.join(out, "bad_nan.h5"), "w") as f:
        f.create_dataset("verts", data=nan, compression="gzip")
        f["tris"] = faces
    with h5py.File(os.path.join(out, "bad_int.h5"), "w") as f:
        f["verts"] = frames.astype(np.int32)
        f["tris"] = faces
    good = os.path.join(out, "splocs.h5")
    data = open(good, "rb").read()
    with open(os.path.join(out, "bad_truncated.h5"), "wb") as f:
        f.write(data[: len(data) // 2])
    with h5py.File(os.path.join(out, "bad_huge_chunked.h5"), "w") as f:
        f.create_dataset("verts", shape=(10**9, n, 3), dtype="f4", chunks=(1, n, 3), compression="gzip")
        f["tris"] = faces
    with h5py.File(os.path.join(out, "bad_partial.h5"), "w") as f:
        d = f.create_dataset("verts", shape=(2 * frames.shape[0], n, 3), dtype="f4", chunks=(1, n, 3), compression="gzip")
        d[: frames.shape[0]] = frames
        f["tris"] = faces
    with h5py.File(os.path.join(out, "bad_huge.h5"), "w") as f:
        f.create_dataset("verts", shape=(10**9, n, 3), dtype="f4")
        f["tris"] = faces
    sizes = {name: os.path.getsize(os.path.join(out, name)) for name in sorted(os.listdir(out)) if name.endswith(".h5")}
    print(json.dumps({"frames": list(frames.shape), "h5py": h5py.__version__, "hdf5": h5py.version.hdf5_version, "sizes": sizes}))


def read_export(path):
    out = {}
    with h5py.File(path, "r") as f:
        for name in f.keys():
            d = f[name]
            out[name] = {"shape": list(d.shape), "dtype": str(d.dtype), "values": d[()].tolist()}
    print(json.dumps(out))


if __name__ == "__main__":
    if sys.argv[1] == "write":
        write(*sys.argv[2:5])
    elif sys.argv[1] == "read-export":
        read_export(sys.argv[2])
    else:
        sys.exit(f"unknown command {sys.argv[1]}")
