"""Fogsmith import for Blender 4.2 and later: File > Import > Fogsmith Fog.

Brings a Fogsmith export into the scene ready to render in Cycles like `fogsmith render`,
with none of the hand steps a plain import needs:

- a USD stage (`fogsmith export --usd`) goes through Blender's own USD importer; a VDB
  (`fogsmith export --vdb`, one file or the first of a numbered sequence) through its
  OpenVDB importer;
- the fog volume gets a Principled Volume: density 1 reading the `density` grid (extinction
  in 1/m), colour = the medium's albedo, anisotropy = its g (from the stage's
  `fogsmith:albedo` and `fogsmith:anisotropy`, or the VDB's `fogsmith_albedo` and
  `fogsmith_anisotropy` metadata);
- a light bake (an `emission` grid, `--bake-light`) renders as emission and absorption: black
  scattering and absorption colours, the `emission` grid into Emission Color at strength 1
  (Cycles' volume emission is radiance per metre, the bake's W·m⁻³·sr⁻¹), and the stage's
  lights hidden from the render, since their light is in the bake;
- Cycles samples a VDB's voxel i at index i + 1/2 while OpenVDB and Fogsmith put it at i:
  the volume moves back by half a voxel along each of its grid axes;
- point and spot lights lose Blender's soft falloff (Fogsmith's lights are exact inverse
  square);
- an animated stage sets the scene's frame rate to the stage's `framesPerSecond`, and a VDB
  sequence starts at its first frame with no offset.
"""

import os
import re
import struct

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty
from bpy_extras.io_utils import ImportHelper
from mathutils import Matrix, Vector

bl_info = {
    "name": "Fogsmith import",
    "author": "Fogsmith",
    "version": (1, 0, 0),
    "blender": (4, 2, 0),
    "location": "File > Import > Fogsmith Fog (.usda, .usd, .vdb)",
    "description": "Import Fogsmith fog (USD stage or OpenVDB) with its material, voxel placement and lights",
    "category": "Import-Export",
}

MATERIAL_LIT = "Fogsmith Fog"
MATERIAL_BAKED = "Fogsmith Baked Light"


class FogsmithImportError(Exception):
    """A file this add-on cannot import, with what to do about it."""


# ---------------------------------------------------------------------------------------------
# What the files say about the medium
# ---------------------------------------------------------------------------------------------


def stage_medium(path):
    """The albedo, anisotropy and frame rate (None for a still) a Fogsmith stage records.

    An ASCII layer (what Fogsmith writes) is read as text; a binary one through USD's Python
    module, after Blender's importer has loaded its own USD libraries."""
    with open(path, "rb") as f:
        head = f.read(5)
    if head == b"#usda":
        with open(path, "rb") as f:
            return _usda_medium(f.read().decode("utf-8", "replace"))
    try:
        from pxr import Usd
    except ImportError as e:
        raise FogsmithImportError(f"{path}: a binary USD file needs USD's Python module (pxr), which is missing") from e
    stage = Usd.Stage.Open(path)
    if stage is None:
        raise FogsmithImportError(f"{path}: not a USD stage Blender can open")
    medium = {"albedo": None, "anisotropy": None, "fps": None, "suns": {}}
    for prim in stage.Traverse():
        if prim.GetTypeName() == "DistantLight":
            attr = prim.GetAttribute("fogsmith:irradiance")
            if attr and attr.HasAuthoredValue():
                medium["suns"][prim.GetName()] = float(attr.Get())
    for prim in stage.Traverse():
        if prim.GetTypeName() != "Volume":
            continue
        for key, name in (("albedo", "fogsmith:albedo"), ("anisotropy", "fogsmith:anisotropy")):
            attr = prim.GetAttribute(name)
            if attr and attr.HasAuthoredValue():
                medium[key] = float(attr.Get())
        break
    if stage.HasAuthoredMetadata("framesPerSecond") and stage.GetEndTimeCode() > stage.GetStartTimeCode():
        medium["fps"] = float(stage.GetFramesPerSecond())
    return medium


def _usda_medium(text):
    def number(pattern):
        m = re.search(pattern + r"\s*=\s*([-+0-9.eE]+)", text)
        return float(m.group(1)) if m else None

    fps = number(r"\bframesPerSecond")
    start, end = number(r"\bstartTimeCode"), number(r"\bendTimeCode")
    animated = fps is not None and start is not None and end is not None and end > start
    suns = {
        m.group(1): float(m.group(2))
        for m in re.finditer(r'def DistantLight "(\w+)"[^}]*?fogsmith:irradiance\s*=\s*([-+0-9.eE]+)', text)
    }
    return {
        "albedo": number(r"fogsmith:albedo"),
        "anisotropy": number(r"fogsmith:anisotropy"),
        "fps": fps if animated else None,
        "suns": suns,
    }


def _read_string(f):
    (n,) = struct.unpack("<I", f.read(4))
    if n > 1 << 20:
        raise ValueError("string too long")
    return f.read(n).decode("utf-8", "replace")


def vdb_medium(path):
    """The albedo and anisotropy in a Fogsmith VDB's file metadata (None where absent), and its
    grid names as the file lists them."""
    medium = {"albedo": None, "anisotropy": None, "fps": None}
    try:
        with open(path, "rb") as f:
            magic, version = struct.unpack("<qI", f.read(12))
            if magic != 0x56444220:
                raise FogsmithImportError(f"{path}: not an OpenVDB file")
            f.read(8)  # library version
            (has_offsets,) = struct.unpack("<B", f.read(1))
            f.read(36)  # uuid
            (count,) = struct.unpack("<I", f.read(4))
            for _ in range(min(count, 4096)):
                name, kind = _read_string(f), _read_string(f)
                (size,) = struct.unpack("<I", f.read(4))
                value = f.read(size)
                if kind == "float" and size == 4:
                    v = struct.unpack("<f", value)[0]
                elif kind == "double" and size == 8:
                    v = struct.unpack("<d", value)[0]
                else:
                    continue
                if name == "fogsmith_albedo":
                    medium["albedo"] = v
                elif name == "fogsmith_anisotropy":
                    medium["anisotropy"] = v
                elif name == "fps":
                    medium["fps"] = v
    except (OSError, struct.error, ValueError) as e:
        raise FogsmithImportError(f"{path}: cannot read its header ({e})") from e
    return medium


# ---------------------------------------------------------------------------------------------
# The scene set-up
# ---------------------------------------------------------------------------------------------


def centre_voxels(vol):
    """Moves the volume back by half a voxel along each axis of its density grid, in the
    object's own space (so a stage under a rotated up-axis root moves correctly too)."""
    vol.data.grids.load()
    grids = vol.data.grids
    grid = grids.get("density") or (grids[0] if len(grids) else None)
    if grid is None:
        return
    m = grid.matrix_object
    half_voxel = Vector([0.5 * (m[r][0] + m[r][1] + m[r][2]) for r in range(3)])
    vol.matrix_basis = vol.matrix_basis @ Matrix.Translation(-half_voxel)


def lit_material(vol, albedo, anisotropy):
    """A Principled Volume whose extinction is the `density` grid, albedo as its colour."""
    mat = bpy.data.materials.new(MATERIAL_LIT)
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    pv = nodes.new("ShaderNodeVolumePrincipled")
    pv.inputs["Density"].default_value = 1.0
    pv.inputs["Density Attribute"].default_value = "density"
    pv.inputs["Color"].default_value = (albedo, albedo, albedo, 1.0)
    pv.inputs["Anisotropy"].default_value = anisotropy
    out = nodes.new("ShaderNodeOutputMaterial")
    out.location = (300, 0)
    mat.node_tree.links.new(pv.outputs["Volume"], out.inputs["Volume"])
    vol.data.materials.clear()
    vol.data.materials.append(mat)
    return mat


def baked_material(vol):
    """Emission and absorption: no scattering, the `emission` grid as emitted radiance."""
    mat = lit_material(vol, 0.0, 0.0)
    mat.name = MATERIAL_BAKED
    tree = mat.node_tree
    pv = tree.nodes["Principled Volume"]
    pv.inputs["Absorption Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    pv.inputs["Emission Strength"].default_value = 1.0
    attr = tree.nodes.new("ShaderNodeAttribute")
    attr.attribute_name = "emission"
    attr.location = (-300, -200)
    tree.links.new(attr.outputs["Color"], pv.inputs["Emission Color"])
    return mat


def grid_names(vol):
    vol.data.grids.load()
    return [g.name for g in vol.data.grids]


def set_up(context, new_objects, medium, lighting, report):
    """Material, voxel placement, lights and frame rate for the objects an import made."""
    scene = context.scene
    volumes = [o for o in new_objects if o.type == "VOLUME"]
    lights = [o for o in new_objects if o.type == "LIGHT"]
    if not volumes:
        raise FogsmithImportError("the file holds no fog volume")
    albedo = medium["albedo"] if medium["albedo"] is not None else 1.0
    anisotropy = medium["anisotropy"] if medium["anisotropy"] is not None else 0.0
    if medium["albedo"] is None:
        report({"WARNING"}, "no fogsmith albedo in the file: the fog's colour is 1 (white)")
    baked_any = False
    for vol in volumes:
        if vol.data.is_sequence:
            # The first file is the first frame: no offset, grids read at that frame.
            vol.data.frame_offset = 0
            scene.frame_set(vol.data.frame_start)
        names = grid_names(vol)
        if "density" not in names:
            raise FogsmithImportError(f"volume {vol.name!r} has no density grid (grids: {', '.join(names)})")
        baked = lighting == "BAKED" or (lighting == "AUTO" and "emission" in names)
        if baked and "emission" not in names:
            raise FogsmithImportError(
                f"volume {vol.name!r} has no emission grid: export with --bake-light, or import with Lighting = Lit"
            )
        if baked:
            baked_material(vol)
            baked_any = True
        else:
            lit_material(vol, albedo, anisotropy)
        centre_voxels(vol)
    suns = medium.get("suns") or {}
    for o in lights:
        if o.data.type in {"POINT", "SPOT"}:
            o.data.use_soft_falloff = False
        if o.data.type == "SUN" and o.name in suns:
            # Blender's USD importer makes a DistantLight of intensity E a sun of strength
            # 4·E; a Fogsmith sun of irradiance E is a sun of strength E.
            o.data.energy = suns[o.name]
        if baked_any:
            # The bake holds their light; rendering them too would light the fog twice.
            o.hide_render = True
            o.hide_viewport = True
    if medium["fps"]:
        fps = medium["fps"]
        scene.render.fps = max(1, round(fps))
        scene.render.fps_base = scene.render.fps / fps
    cameras = [o for o in new_objects if o.type == "CAMERA"]
    if cameras and scene.camera is None:
        scene.camera = cameras[0]
    return volumes, lights


def import_usd(context, path, lighting, report):
    before = set(bpy.data.objects)
    result = bpy.ops.wm.usd_import(filepath=path)
    if "FINISHED" not in result:
        raise FogsmithImportError(f"{path}: Blender's USD importer refused the stage")
    medium = stage_medium(path)
    new = [o for o in bpy.data.objects if o not in before]
    return set_up(context, new, medium, lighting, report)


def sequence_files(path):
    """The files of the numbered sequence `path` belongs to (just `path` without a number)."""
    folder, name = os.path.split(path)
    m = re.match(r"^(.*?)(\d+)(\.vdb)$", name)
    if not m:
        return [name]
    prefix, digits, ext = m.groups()
    pattern = re.compile(re.escape(prefix) + r"\d{" + str(len(digits)) + r"}" + re.escape(ext) + "$")
    files = sorted(f for f in os.listdir(folder or ".") if pattern.match(f))
    return files or [name]


def import_vdb(context, path, lighting, report):
    medium = vdb_medium(path)
    folder = os.path.dirname(path)
    files = sequence_files(path)
    before = set(bpy.data.objects)
    result = bpy.ops.object.volume_import(
        filepath=path, directory=folder + os.sep, files=[{"name": f} for f in files], use_sequence_detection=True
    )
    if "FINISHED" not in result:
        raise FogsmithImportError(f"{path}: Blender's OpenVDB importer refused the file")
    new = [o for o in bpy.data.objects if o not in before]
    return set_up(context, new, medium, lighting, report)


def import_fogsmith(context, path, lighting="AUTO", report=None):
    """Imports `path` (.usda, .usdc, .usd or .vdb) and sets it up; returns the volumes and
    lights it made. Raises FogsmithImportError with the reason and the fix."""

    def quiet(_level, _message):
        pass

    report = report or quiet
    if not os.path.isfile(path):
        raise FogsmithImportError(f"{path}: no such file")
    ext = os.path.splitext(path)[1].lower()
    if ext in {".usda", ".usdc", ".usd"}:
        return import_usd(context, path, lighting, report)
    if ext == ".vdb":
        return import_vdb(context, path, lighting, report)
    raise FogsmithImportError(f"{path}: not a Fogsmith export (choose a .usda, .usd, .usdc or .vdb file)")


# ---------------------------------------------------------------------------------------------
# Blender's side
# ---------------------------------------------------------------------------------------------


class IMPORT_SCENE_OT_fogsmith(bpy.types.Operator, ImportHelper):
    """Import a Fogsmith USD stage or OpenVDB file, ready to render in Cycles"""

    bl_idname = "import_scene.fogsmith"
    bl_label = "Import Fogsmith Fog"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filter_glob: StringProperty(default="*.usda;*.usdc;*.usd;*.vdb", options={"HIDDEN"})
    lighting: EnumProperty(
        name="Lighting",
        description="How the fog is lit",
        items=(
            ("AUTO", "Auto", "Baked light when the file has an emission grid, else lit by the lights"),
            ("LIT", "Lit", "Scattering lit by the scene's lights (Principled Volume with the albedo)"),
            ("BAKED", "Baked", "Emission and absorption from the light bake's emission grid, lights hidden"),
        ),
        default="AUTO",
    )
    use_cycles: BoolProperty(
        name="Set up Cycles",
        description="Switch the render engine to Cycles, which renders the volume as Fogsmith does",
        default=True,
    )

    def execute(self, context):
        try:
            volumes, lights = import_fogsmith(context, self.filepath, self.lighting, self.report)
        except FogsmithImportError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        if self.use_cycles:
            context.scene.render.engine = "CYCLES"
        self.report({"INFO"}, f"Fogsmith: {len(volumes)} volume(s), {len(lights)} light(s)")
        return {"FINISHED"}


def menu_import(self, _context):
    self.layout.operator(IMPORT_SCENE_OT_fogsmith.bl_idname, text="Fogsmith Fog (.usda, .usd, .vdb)")


def register():
    bpy.utils.register_class(IMPORT_SCENE_OT_fogsmith)
    bpy.types.TOPBAR_MT_file_import.append(menu_import)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(menu_import)
    bpy.utils.unregister_class(IMPORT_SCENE_OT_fogsmith)
