"""Opens an animated .usda stage with Pixar's USD (usd-core) and prints what it reads as JSON.

Usage: .venv/bin/python tests/usd_sequence_check.py STAGE.usda
The stage's start and end time codes, time codes and frames per second; per volume field
its filePath time samples as [time, resolved path]; per SphereLight the number of time
samples of its transform and its world position at every frame; the camera's world
position at every frame; and the errors USD's validators report.
"""
import json
import sys

from pxr import Sdf, Usd, UsdGeom, UsdLux, UsdValidation, UsdVol


def vec(v):
    return [float(c) for c in v]


path = sys.argv[1]
layer = Sdf.Layer.FindOrOpen(path)
if layer is None:
    sys.exit(f"usd_sequence_check: {path} is not a USD layer USD can open")
stage = Usd.Stage.Open(layer)
start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
frames = [Usd.TimeCode(t) for t in range(int(start), int(end) + 1)]
out = {
    "start": start,
    "end": end,
    "tcps": stage.GetTimeCodesPerSecond(),
    "fps": stage.GetFramesPerSecond(),
    "fields": {},
    "lights": {},
}
vol = UsdVol.Volume(stage.GetPrimAtPath("/World/Fog"))
for name, fpath in vol.GetFieldPaths().items():
    attr = UsdVol.OpenVDBAsset(stage.GetPrimAtPath(fpath)).GetFilePathAttr()
    out["fields"][name] = [[t, attr.Get(t).resolvedPath] for t in attr.GetTimeSamples()]
for prim in stage.Traverse():
    if prim.IsA(UsdLux.SphereLight):
        xf = UsdGeom.Xformable(prim)
        samples = sum(len(op.GetAttr().GetTimeSamples()) for op in xf.GetOrderedXformOps())
        out["lights"][prim.GetName()] = {
            "samples": samples,
            "positions": [vec(xf.ComputeLocalToWorldTransform(t).ExtractTranslation()) for t in frames],
        }
    elif prim.IsA(UsdGeom.Camera):
        cam = UsdGeom.Camera(prim)
        out["camera"] = [vec(cam.GetCamera(t).transform.ExtractTranslation()) for t in frames]
validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
errors = UsdValidation.ValidationContext(validators).Validate(stage)
out["errors"] = [f"{e.GetName()}: {e.GetMessage()}" for e in errors]
print(json.dumps(out))
