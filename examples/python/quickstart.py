"""meshdeco from Python in one page: load SCAPE, train SPLOCS from in-memory arrays, look at a
component's heat map, pose the body by dragging a vertex, export a glTF with morph targets.

    pip install ./python                 # once, from the repository root
    python examples/python/quickstart.py [--data ../shared/data/scape] [--out target/tmp/quickstart]

Without ../shared/data it falls back to the built-in synthetic tube. The heat map is drawn with
matplotlib when it is installed (pip install matplotlib), else skipped.
"""

import argparse
import os
import time

import numpy as np

import meshdeco

p = argparse.ArgumentParser()
p.add_argument("--data", default="../shared/data/scape")
p.add_argument("--out", default="target/tmp/quickstart")
a = p.parse_args()
os.makedirs(a.out, exist_ok=True)

# 1. Frames that share one connectivity: float64 (F, N, 3) and int64 (T, 3).
source = a.data if os.path.isdir(a.data) else "synthetic:tube"
frames, faces = meshdeco.load_sequence(source)
print(f"{source}: {frames.shape[0]} frames, {frames.shape[1]} vertices, {faces.shape[0]} triangles")

# 2. SPLOCS with the settings of configs/scape-splocs.toml, as a dict, on the arrays (no files).
config = {
    "name": "quickstart-splocs",
    "data": {"train": "1-36", "test": "37-71" if frames.shape[0] >= 71 else "rest", "unit_box": True},
    "method": {"kind": "splocs", "components": 50, "sparsity": 2.0, "support": [0.1, 0.7], "seed": 0},
}
t = time.time()
model = meshdeco.train(config, frames, faces, out=os.path.join(a.out, "model"))
m = model.metrics
print(f"trained {model} in {time.time() - t:.1f} s: train Erms {m['train_erms']:.3f}, test Erms {m['test_erms']:.3f}")

# 3. Components: ranked, named, with a per-vertex heat map (N,).
comps = sorted(model.components(), key=lambda c: c["rank"])
c = comps[0]
print(f"component {c['name']}: centre vertex {c['centre']}, peak magnitude {c['magnitude'].max():.4f}")
try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rest = model.rest
    up = int(np.argmax(np.ptp(rest, axis=0)))  # the tallest axis is drawn vertically
    side = [k for k in range(3) if k != up][0]
    fig, ax = plt.subplots(figsize=(4, 6))
    sc = ax.scatter(rest[:, side], rest[:, up], c=c["magnitude"], s=2, cmap="inferno")
    ax.set_aspect("equal")
    ax.set_title(f"component {c['name']}")
    fig.colorbar(sc, ax=ax, label="magnitude (data units)")
    png = os.path.join(a.out, "component-heat-map.png")
    fig.savefig(png, dpi=120)
    print(f"heat map: {png}")
except ImportError:
    print("matplotlib is not installed: heat map skipped")

# 4. Encode the test frames, decode them back (batched), and measure the error ourselves.
test = frames[36:] if frames.shape[0] >= 71 else frames[1::2]
rec = model.decode(model.encode(test))
print(f"test reconstruction: max vertex error {np.linalg.norm(rec - test, axis=2).max():.4f} data units")

# 5. Pose: drag the first component's centre 5 % of the body's height along the up axis.
v = int(c["centre"])
height = np.ptp(model.rest, axis=0).max()
target = model.rest[v] + 0.05 * height * np.eye(3)[int(np.argmax(np.ptp(model.rest, axis=0)))]
pose = model.pose({v: target})
print(f"pose: vertex {v} moved {np.linalg.norm(pose.positions[v] - model.rest[v]):.4f} of {0.05 * height:.4f}")
meshdeco.save_mesh(os.path.join(a.out, "posed.obj"), pose.positions, model.faces)

# 6. Export: glTF 2.0 with one morph target per component and the training frames as animation.
report = model.export(os.path.join(a.out, "model.glb"), animation=True)
print(f"export: {report['targets']} morph targets, {report['animation_frames']} keys, {report['bytes']} bytes")
