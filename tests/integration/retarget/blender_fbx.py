# Blender's own FBX importer reads an FBX kinemo wrote (assimp's exporter)
# and Blender's own BVH importer the BVH of the same retargeting; prints one
# JSON line comparing a bone's world position in the two at a few frames:
#   blender -b --factory-startup --python blender_fbx.py -- OUT.fbx OUT.bvh BONE F1,F2,...
# {"fbx", "bvh", "bone", "frames": [{"frame", "fbx": [x,y,z], "bvh": [x,y,z], "distance_m"}],
#  "max_distance_m", "skinned_meshes", "fbx_frames", "bvh_frames", "armatures", "error"}
# Frames count from 0 (the files' first frame). Exit code 0 once both
# imported (the checks are the caller's), 1 when an import failed.
import json
import sys

import bpy

args = sys.argv[sys.argv.index("--") + 1:]
fbx_path, bvh_path, bone = args[0], args[1], args[2]
frames = [int(f) for f in args[3].split(",")]
report = {"fbx": fbx_path, "bvh": bvh_path, "bone": bone, "error": ""}


def armature_of(before):
    new = [o for o in bpy.data.objects if o.type == "ARMATURE" and o.name not in before]
    if len(new) != 1:
        raise RuntimeError("expected one new armature, got %d" % len(new))
    return new[0]


def frame_range(obj):
    action = obj.animation_data.action if obj.animation_data else None
    if action is None:
        raise RuntimeError("%s has no animation" % obj.name)
    return action.frame_range


try:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    # Debian 12's Blender 3.4.1 runs Python 3.11, in which open() no longer
    # takes the "U" mode its BVH importer still asks for (fixed upstream in
    # Blender 3.5 by opening with "r"): the importer's module gets an open()
    # that drops the "U", and is otherwise Blender's own.
    import builtins
    from io_anim_bvh import import_bvh

    def _open(file, mode="r", *rest, **named):
        return builtins.open(file, mode.replace("U", ""), *rest, **named)

    import_bvh.open = _open
    before = {o.name for o in bpy.data.objects}
    # The BVH first: it sets the scene's frame rate to the file's.
    result = bpy.ops.import_anim.bvh(filepath=bvh_path, global_scale=1.0, frame_start=1, use_fps_scale=False,
                                     update_scene_fps=True, update_scene_duration=True, axis_forward="-Z",
                                     axis_up="Y")
    if "FINISHED" not in result:
        raise RuntimeError("import_anim.bvh returned %s" % (result,))
    bvh = armature_of(before)
    before = {o.name for o in bpy.data.objects}
    result = bpy.ops.import_scene.fbx(filepath=fbx_path, use_anim=True, anim_offset=1.0)
    if "FINISHED" not in result:
        raise RuntimeError("import_scene.fbx returned %s" % (result,))
    fbx = armature_of(before)
    report["armatures"] = len([o for o in bpy.data.objects if o.type == "ARMATURE"])
    report["bvh_frames"] = list(frame_range(bvh))
    report["fbx_frames"] = list(frame_range(fbx))
    if bone not in fbx.pose.bones or bone not in bvh.pose.bones:
        raise RuntimeError("bone %s missing (fbx has it: %s, bvh: %s)" % (bone, bone in fbx.pose.bones,
                                                                          bone in bvh.pose.bones))
except Exception as e:  # the importers raise on files they refuse
    report["error"] = "%s: %s" % (type(e).__name__, e)
    print("KINEMO_BLENDER " + json.dumps(report))
    sys.stdout.flush()
    sys.exit(1)

scene = bpy.context.scene
out = []
worst = 0.0
for f in frames:
    scene.frame_set(f + 1)
    a = fbx.matrix_world @ fbx.pose.bones[bone].head
    b = bvh.matrix_world @ bvh.pose.bones[bone].head
    d = (a - b).length
    worst = max(worst, d)
    out.append({"frame": f, "fbx": [round(v, 5) for v in a], "bvh": [round(v, 5) for v in b], "distance_m": d})
report["frames"] = out
report["max_distance_m"] = worst
# The character's meshes, deformed by the imported armature.
report["skinned_meshes"] = len([o for o in bpy.data.objects if o.type == "MESH" and any(
    m.type == "ARMATURE" and m.object == fbx for m in o.modifiers)])
print("KINEMO_BLENDER " + json.dumps(report))
sys.stdout.flush()
