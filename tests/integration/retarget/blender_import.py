# Blender's own glTF importer reads a GLB kinemo wrote; prints one JSON line
# describing what it imported:
#   blender -b --factory-startup --python blender_import.py -- OUT.glb
# {"file", "armatures", "bone_fcurves", "bones_moving", "bone_range_deg",
#  "meshes_with_shape_keys", "shape_key_fcurves", "shape_keys_changing",
#  "shape_key_range", "frames", "error"}
# A bone "moves" when one of its rotation fcurves spans more than 1 degree
# (quaternion components: 0.01); a shape key "changes" when its value fcurve
# spans more than 0.05. Exit code 0 once the file imported (the checks are the
# caller's), 1 when the import failed.
import json
import math
import sys

import bpy
import numpy

# Debian 12's Blender 3.4.1 ships a glTF importer that still uses numpy's
# `np.bool` alias, which numpy 1.24 (Debian 12's) removed: every mesh import
# fails with "module 'numpy' has no attribute 'bool'" (KhronosGroup/
# glTF-Blender-IO#1844, fixed upstream by #1831 in Blender 3.5 by writing
# `bool`). The alias is restored here exactly as upstream's fix reads it; the
# importer is otherwise Blender's own.
if not hasattr(numpy, "bool") or numpy.__version__ >= "1.24":
    numpy.bool = bool

path = sys.argv[sys.argv.index("--") + 1]
report = {"file": path, "error": ""}
try:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.import_scene.gltf(filepath=path)
    if "FINISHED" not in result:
        raise RuntimeError("import_scene.gltf returned %s" % (result,))
except Exception as e:  # the importer raises on files it refuses
    report["error"] = "%s: %s" % (type(e).__name__, e)
    print("KINEMO_BLENDER " + json.dumps(report))
    sys.stdout.flush()
    sys.exit(1)


def fcurve_span(fc):
    values = [k.co[1] for k in fc.keyframe_points]
    return (max(values) - min(values)) if values else 0.0


armatures = [o for o in bpy.data.objects if o.type == "ARMATURE"]
bone_fcurves = 0
moving = set()
widest = 0.0
frames = 0
for arm in armatures:
    action = arm.animation_data.action if arm.animation_data else None
    if action is None:
        continue
    frames = max(frames, int(action.frame_range[1] - action.frame_range[0]) + 1)
    for fc in action.fcurves:
        if not fc.data_path.startswith("pose.bones"):
            continue
        bone_fcurves += 1
        span = fcurve_span(fc)
        if fc.data_path.endswith("rotation_quaternion"):
            widest = max(widest, 2 * math.degrees(math.asin(min(1.0, span / 2))))
            if span > 0.01:
                moving.add(fc.data_path.split('"')[1])
        elif fc.data_path.endswith("rotation_euler"):
            widest = max(widest, math.degrees(span))
            if span > math.radians(1):
                moving.add(fc.data_path.split('"')[1])

shape_meshes = []
key_fcurves = 0
changing = []
key_range = 0.0
for mesh in bpy.data.meshes:
    key = mesh.shape_keys
    if key is None:
        continue
    shape_meshes.append(mesh.name)
    action = key.animation_data.action if key.animation_data else None
    if action is None:
        continue
    for fc in action.fcurves:
        if not fc.data_path.startswith("key_blocks"):
            continue
        key_fcurves += 1
        span = fcurve_span(fc)
        key_range = max(key_range, span)
        if span > 0.05:
            changing.append(mesh.name + "/" + fc.data_path.split('"')[1])

report.update({
    "armatures": len(armatures),
    "bone_fcurves": bone_fcurves,
    "bones_moving": len(moving),
    "bone_range_deg": round(widest, 2),
    "meshes_with_shape_keys": shape_meshes,
    "shape_key_fcurves": key_fcurves,
    "shape_keys_changing": len(changing),
    "shape_keys_changing_names": sorted(changing)[:40],
    "shape_key_range": round(key_range, 3),
    "frames": frames,
})
print("KINEMO_BLENDER " + json.dumps(report))
sys.stdout.flush()
