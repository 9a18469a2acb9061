# Imports a .glb with Blender's glTF importer and prints each mesh's vertex and shape-key counts:
#   blender --background --factory-startup --python tests/blender/import_glb.py -- model.glb
# (a manual check, not part of `cargo test`: Debian's blender is large.)
import bpy, sys
import numpy
if not hasattr(numpy, "bool"):
    numpy.bool = bool  # Debian blender 3.4 importer vs numpy 1.24
path = sys.argv[sys.argv.index("--") + 1]
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=path)
for o in bpy.data.objects:
    if o.type == 'MESH':
        keys = o.data.shape_keys.key_blocks if o.data.shape_keys else []
        print("BLENDER", o.name, "vertices", len(o.data.vertices), "shape keys", len(keys), "(incl. Basis)", [k.name for k in keys][:4])
