"""An empty Blender scene, shared by the tests' `scene` fixture and the benchmarks
(bench/benchutil.py puts tests/ on sys.path).  No pytest here."""


def empty_scene(bpy):
    """Leave Edit Mode, remove every object, mesh and unused material; return the scene."""
    if bpy.context.object is not None and bpy.context.object.mode != "OBJECT":
        bpy.ops.object.mode_set(mode="OBJECT")
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob, do_unlink=True)
    for me in list(bpy.data.meshes):
        bpy.data.meshes.remove(me)
    for mat in list(bpy.data.materials):
        if mat.users == 0:
            bpy.data.materials.remove(mat)
    return bpy.context.scene
