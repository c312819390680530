# Makes the FBX test rigs of this folder from the Quaternius man (CC0) with
# Blender's own glTF importer and FBX exporter (not with kinemo):
#
#   blender -b --factory-startup --python make_fbx.py -- \
#       ../quaternius_man_casual.glb OUT.fbx [quaternius|mixamo|cc] [armature]
#
# `mixamo` renames the bones before exporting to the names Mixamo's rigs use
# (`mixamorig:Hips`, `mixamorig:LeftArm`, `mixamorig:LeftHandIndex1`, ...),
# `cc` to Character Creator's (`CC_Base_Hip`, `CC_Base_L_Upperarm`,
# `CC_Base_L_Index1`, ...), so that kinemo's name mapping is tested on FBX
# files of those families. `armature` exports the skeleton alone (no mesh). The export
# uses the exporter's defaults (which is what a user gets from File > Export >
# FBX) except: no animation (the rig only), leaf bones only for the skeleton
# alone (below), textures not embedded (the man has none).
import sys

import bpy
import numpy

# Debian 12's Blender 3.4.1 glTF importer still uses numpy's removed `np.bool`
# alias (KhronosGroup/glTF-Blender-IO#1844; fixed upstream in Blender 3.5):
# restored as upstream's fix reads it (see tests/integration/retarget/blender_import.py).
if not hasattr(numpy, "bool") or numpy.__version__ >= "1.24":
    numpy.bool = bool

args = sys.argv[sys.argv.index("--") + 1:]
src, out = args[0], args[1]
names = args[2] if len(args) > 2 else "quaternius"
armature_only = len(args) > 3 and args[3] == "armature"

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=src)

# Per family: trunk names, side-bone pattern ({s} = side), finger pattern
# ({f} = finger, {n} = number), side tokens, finger names.
FAMILIES = {
    "mixamo": (
        {"Hips": "mixamorig:Hips", "Abdomen": "mixamorig:Spine", "Torso": "mixamorig:Spine1",
         "Chest": "mixamorig:Spine2", "Neck": "mixamorig:Neck", "Head": "mixamorig:Head"},
        {"Shoulder": "mixamorig:{s}Shoulder", "UpperArm": "mixamorig:{s}Arm", "LowerArm": "mixamorig:{s}ForeArm",
         "Hand": "mixamorig:{s}Hand", "UpperLeg": "mixamorig:{s}UpLeg", "LowerLeg": "mixamorig:{s}Leg",
         "Foot": "mixamorig:{s}Foot"},
        "mixamorig:{s}Hand{f}{n}", ("Left", "Right"),
        {"Thumb": "Thumb", "Index": "Index", "Middle": "Middle", "Ring": "Ring", "Pinky": "Pinky"}),
    "cc": (
        {"Hips": "CC_Base_Hip", "Abdomen": "CC_Base_Waist", "Torso": "CC_Base_Spine01",
         "Chest": "CC_Base_Spine02", "Neck": "CC_Base_NeckTwist01", "Head": "CC_Base_Head"},
        {"Shoulder": "CC_Base_{s}_Clavicle", "UpperArm": "CC_Base_{s}_Upperarm", "LowerArm": "CC_Base_{s}_Forearm",
         "Hand": "CC_Base_{s}_Hand", "UpperLeg": "CC_Base_{s}_Thigh", "LowerLeg": "CC_Base_{s}_Calf",
         "Foot": "CC_Base_{s}_Foot"},
        "CC_Base_{s}_{f}{n}", ("L", "R"),
        {"Thumb": "Thumb", "Index": "Index", "Middle": "Mid", "Ring": "Ring", "Pinky": "Pinky"}),
}


def renamed(name, family):
    trunk, side_bones, finger_pattern, sides, fingers = FAMILIES[family]
    if name in trunk:
        return trunk[name]
    if name.endswith(".L") or name.endswith(".R"):
        side = sides[0] if name.endswith(".L") else sides[1]
        base = name[:-2]
        if base in side_bones:
            return side_bones[base].replace("{s}", side)
        for q, f in fingers.items():
            if base.startswith(q) and base[len(q):].isdigit():
                # Quaternius numbers the finger phalanges from 2 (Index2 is
                # the proximal one) and the thumb's from 1 (Thumb2 is its
                # second bone); Mixamo and CC number both from 1.
                n = int(base[len(q):]) - (0 if q == "Thumb" else 1)
                return finger_pattern.replace("{s}", side).replace("{f}", f).replace("{n}", str(n))
    return None


if names in FAMILIES:
    for arm in [o for o in bpy.data.objects if o.type == "ARMATURE"]:
        for bone in arm.data.bones:
            new = renamed(bone.name, names)
            if new:
                bone.name = new  # Blender renames the vertex groups with it
elif names != "quaternius":
    raise SystemExit("names must be quaternius, mixamo or cc, got " + names)

if armature_only:
    # As Mixamo's and Character Creator's files have it: the armature at
    # the origin with unit scale, its bones in centimetres (the man's
    # armature hangs under a node scaled 100 times, which puts his bones'
    # translations under a millimetre; assimp drops translations that
    # short from the node tree, docs/retarget.md).
    for arm in [o for o in bpy.data.objects if o.type == "ARMATURE"]:
        bpy.context.view_layer.objects.active = arm
        arm.select_set(True)
        bpy.ops.object.parent_clear(type="CLEAR_KEEP_TRANSFORM")
        bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)
kinds = {"ARMATURE"} if armature_only else {"ARMATURE", "MESH"}
# The skeleton alone gets Blender's leaf bones ("..._end", at each last
# bone's tail: the toe tips), as Mixamo's skeletons have theirs
# (mixamorig:LeftToe_End); with the mesh, the glTF's own "_end" nodes come
# through.
bpy.ops.export_scene.fbx(filepath=out, bake_anim=False, add_leaf_bones=armature_only, embed_textures=False,
                         object_types=kinds)
print("made", out)
