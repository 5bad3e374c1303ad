"""Opens a .usda stage with Pixar's USD (usd-core) and prints what it reads as JSON.

Usage: .venv/bin/python tests/usd_check.py STAGE.usda [STAGE.usda ...]  (one JSON line per stage)
Stage metadata, the volume's fields (their asset paths as written and as resolved, field
names and classes), every SphereLight (world position, intensity, colour, normalize,
treatAsPoint, radius), the camera (world position, view and up directions, vertical and
horizontal field of view), every mesh (world bounds, face count, bound material's
diffuse colour, ior, roughness), and the errors USD's validators report.
"""
import json
import sys

from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, UsdValidation, UsdVol


def vec(v):
    return [float(c) for c in v]


def check(path):
    layer = Sdf.Layer.FindOrOpen(path)
    if layer is None:
        sys.exit(f"usd_check: {path} is not a USD layer USD can open")
    stage = Usd.Stage.Open(layer)
    t = Usd.TimeCode.Default()
    out = {
        "upAxis": UsdGeom.GetStageUpAxis(stage),
        "metersPerUnit": UsdGeom.GetStageMetersPerUnit(stage),
        "defaultPrim": stage.GetDefaultPrim().GetPath().pathString if stage.GetDefaultPrim() else None,
        "creator": layer.customLayerData.get("creator"),
        "prims": {p.GetPath().pathString: p.GetTypeName() for p in stage.Traverse()},
        "fields": {},
        "lights": {},
        "meshes": {},
    }

    vol_prim = stage.GetPrimAtPath("/World/Fog")
    vol = UsdVol.Volume(vol_prim)
    out["volume"] = {
        "is_volume": vol_prim.IsA(UsdVol.Volume),
        "extent": [vec(e) for e in vol.GetExtentAttr().Get()],
        "albedo": vol_prim.GetAttribute("fogsmith:albedo").Get(),
        "anisotropy": vol_prim.GetAttribute("fogsmith:anisotropy").Get(),
        "base_extinction": vol_prim.GetAttribute("fogsmith:baseExtinction").Get(),
    }
    for name, fpath in vol.GetFieldPaths().items():
        prim = stage.GetPrimAtPath(fpath)
        asset = UsdVol.OpenVDBAsset(prim)
        fp = asset.GetFilePathAttr().Get()
        out["fields"][name] = {
            "is_openvdb_asset": prim.IsA(UsdVol.OpenVDBAsset),
            "path": fp.path,
            "resolved": fp.resolvedPath,
            "fieldName": asset.GetFieldNameAttr().Get(),
            "fieldClass": asset.GetFieldClassAttr().Get(),
            "fieldDataType": asset.GetFieldDataTypeAttr().Get(),
        }

    for prim in stage.Traverse():
        if prim.IsA(UsdLux.SphereLight):
            light = UsdLux.SphereLight(prim)
            m = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(t)
            out["lights"][prim.GetName()] = {
                "position": vec(m.ExtractTranslation()),
                "intensity": light.GetIntensityAttr().Get(),
                "color": vec(light.GetColorAttr().Get()),
                "normalize": bool(light.GetNormalizeAttr().Get()),
                "treatAsPoint": bool(light.GetTreatAsPointAttr().Get()),
                "radius": light.GetRadiusAttr().Get(),
            }
        elif prim.IsA(UsdGeom.Camera):
            cam = UsdGeom.Camera(prim).GetCamera(t)
            m = cam.transform
            out["camera"] = {
                "position": vec(m.ExtractTranslation()),
                "forward": vec(m.TransformDir(Gf.Vec3d(0, 0, -1)).GetNormalized()),
                "up": vec(m.TransformDir(Gf.Vec3d(0, 1, 0)).GetNormalized()),
                "fov_y_deg": cam.GetFieldOfView(Gf.Camera.FOVVertical),
                "fov_x_deg": cam.GetFieldOfView(Gf.Camera.FOVHorizontal),
            }
        elif prim.IsA(UsdGeom.Mesh):
            mesh = UsdGeom.Mesh(prim)
            cache = UsdGeom.BBoxCache(t, [UsdGeom.Tokens.default_])
            box = cache.ComputeWorldBound(prim).ComputeAlignedRange()
            material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
            shader = material.ComputeSurfaceSource()[0] if material else None
            get = lambda n: shader.GetInput(n).Get() if shader and shader.GetInput(n) else None
            out["meshes"][prim.GetName()] = {
                "min": vec(box.GetMin()),
                "max": vec(box.GetMax()),
                "faces": len(mesh.GetFaceVertexCountsAttr().Get()),
                "shader": shader.GetIdAttr().Get() if shader else None,
                "diffuseColor": vec(get("diffuseColor")) if get("diffuseColor") is not None else None,
                "ior": get("ior"),
                "roughness": get("roughness"),
            }

    # USD's own validators (the framework behind `usdchecker`), all of those registered.

    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    out["validators"] = len(validators)
    out["validation_errors"] = [f"{e.GetName()}: {e.GetMessage()}" for e in errors]

    return out


for path in sys.argv[1:]:
    print(json.dumps(check(path)))
