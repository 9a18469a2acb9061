"""Opens meshdeco's .usda exports with Pixar's usd-core and runs every validator of its
pxr.UsdValidation registry. Prints one JSON line per file: errors (with their messages),
blend shape count, the animation's time samples and the stage's up axis / metres per unit.
Usage: python validate_usd.py FILE.usda [...]"""
import json
import sys

from pxr import Usd, UsdGeom, UsdSkel, UsdValidation


def check(path):
    stage = Usd.Stage.Open(path)
    registry = UsdValidation.ValidationRegistry()
    validators = registry.GetOrLoadAllValidators()
    context = UsdValidation.ValidationContext(validators)
    errors = context.Validate(stage)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Model/Mesh"))
    binding = UsdSkel.BindingAPI(mesh.GetPrim())
    shapes = binding.GetBlendShapesAttr().Get() or []
    targets = binding.GetBlendShapeTargetsRel().GetTargets()
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/Model/Skel/Anim"))
    samples = anim.GetBlendShapeWeightsAttr().GetTimeSamples() if anim else []
    points = mesh.GetPointsAttr().Get()
    lo = [min(p[i] for p in points) for i in range(3)]
    hi = [max(p[i] for p in points) for i in range(3)]
    tallest = max(range(3), key=lambda i: hi[i] - lo[i])
    return {
        "file": path,
        "validators": len(validators),
        "errors": [str(e.GetMessage()) for e in errors],
        "blend_shapes": len(shapes),
        "blend_shape_targets": len(targets),
        "time_samples": len(samples),
        "up_axis": UsdGeom.GetStageUpAxis(stage),
        "meters_per_unit": UsdGeom.GetStageMetersPerUnit(stage),
        "tallest_axis": "XYZ"[tallest],
        "points": len(points),
    }


for f in sys.argv[1:]:
    print(json.dumps(check(f)))
