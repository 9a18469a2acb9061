"""Throughput of meshdeco.Model.decode on a trained model: 1000 weight vectors decoded in one
batched call, best of --repeats runs; the Rust library's counterpart is
examples/decode_throughput.rs (same weights: row i is the training weights of frame i mod F
scaled by 0.5 + (i mod 7) / 7).

    meshdeco train --config configs/scape-splocs.toml --out target/tmp/scape-splocs
    python examples/python/decode_throughput.py target/tmp/scape-splocs [--repeats 5]
"""

import argparse
import time

import numpy as np

import meshdeco

p = argparse.ArgumentParser()
p.add_argument("model", nargs="?", default="target/tmp/scape-splocs")
p.add_argument("--repeats", type=int, default=5)
a = p.parse_args()
model = meshdeco.load_model(a.model)
train = model.train_weights
i = np.arange(1000)
weights = train[i % len(train)] * (0.5 + (i % 7) / 7.0)[:, None]
best = float("inf")
for _ in range(max(a.repeats, 1)):
    t = time.perf_counter()
    frames = model.decode(weights)
    best = min(best, time.perf_counter() - t)
checksum = frames.sum()
print(
    f"python decode: {len(weights)} weight vectors (K {model.n_components}, N {model.n_vertices}) in {best:.4f} s "
    f"(best of {a.repeats}): {len(weights) / best:.0f} shapes/s; checksum {checksum:.9e}; output {frames.shape} {frames.dtype}"
)
