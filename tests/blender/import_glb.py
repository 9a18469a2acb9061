# Imports .glb files with Blender's glTF importer and prints one JSON line per file: the mesh
# objects' vertex and shape-key counts (Basis included) and the tallest world-space axis of their
# bounding box (Blender is Z-up: a Y-up glTF standing upright stands along Z here).
#   blender --background --factory-startup --python tests/blender/import_glb.py -- a.glb [b.glb ...]
# Run by tests/export_gltf.rs when `blender` is on the PATH (.ci/run installs Debian's).
import json
import sys

import bpy
import numpy

if not hasattr(numpy, "bool"):
    numpy.bool = bool  # Debian blender 3.4 importer vs numpy 1.24

for path in sys.argv[sys.argv.index("--") + 1:]:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=path)
    out = {"file": path, "meshes": []}
    for o in bpy.data.objects:
        if o.type != 'MESH':
            continue
        keys = o.data.shape_keys.key_blocks if o.data.shape_keys else []
        pts = [o.matrix_world @ v.co for v in o.data.vertices]
        ext = [max(p[i] for p in pts) - min(p[i] for p in pts) for i in range(3)]
        out["meshes"].append({
            "name": o.name,
            "vertices": len(o.data.vertices),
            "shape_keys": len(keys),
            "tallest": "XYZ"[ext.index(max(ext))],
        })
    print("BLENDER " + json.dumps(out), flush=True)
