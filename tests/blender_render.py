"""Render an object with Blender's Workbench engine to a PNG (headless), as a photo stand-in for the
retrieval tests: a camera looking at the object's bounding box from a direction, a plain world."""
from __future__ import annotations

import math

import numpy as np


def render_object(bpy, ob, path, direction=(0.3, -1.0, 0.4), size=(400, 300), background=(0.05, 0.05, 0.06),
                  color=(0.8, 0.8, 0.8)) -> str:
    """Render ``ob`` seen from ``direction`` (world, pointing from the object to the camera) into ``path``;
    the other objects are hidden from the render; returns the path."""
    scene = bpy.context.scene
    hidden = [(o, o.hide_render) for o in scene.objects]
    for o, _ in hidden:
        o.hide_render = o is not ob
    corners = np.array([ob.matrix_world @ __import__("mathutils").Vector(c) for c in ob.bound_box])
    centre = corners.mean(axis=0)
    radius = float(np.linalg.norm(corners - centre, axis=1).max())
    d = np.asarray(direction, dtype=np.float64)
    d /= np.linalg.norm(d)
    cam_data = bpy.data.cameras.new("render_cam")
    cam_data.lens = 50.0
    cam = bpy.data.objects.new("render_cam", cam_data)
    scene.collection.objects.link(cam)
    fov = 2 * math.atan(cam_data.sensor_width / (2 * cam_data.lens))
    dist = 1.3 * radius / math.sin(fov / 2 * min(1.0, size[1] / size[0]))
    cam.location = tuple(centre + dist * d)
    cam.rotation_euler = (__import__("mathutils").Vector(tuple(-d))).to_track_quat("-Z", "Y").to_euler()
    cam_data.clip_end = dist + 4 * radius
    cam_data.clip_start = max(dist - 4 * radius, 1e-4)
    old_camera, old_engine = scene.camera, scene.render.engine
    scene.camera = cam
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    shading = scene.display.shading
    shading.light = "STUDIO"
    shading.color_type = "SINGLE"
    shading.single_color = color
    shading.background_type = "VIEWPORT"
    shading.background_color = background
    if scene.world is None:
        scene.world = bpy.data.worlds.new("World")
    scene.world.color = background
    scene.render.filepath = str(path)
    try:
        bpy.ops.render.render(write_still=True)
    finally:
        scene.camera, scene.render.engine = old_camera, old_engine
        bpy.data.objects.remove(cam, do_unlink=True)
        bpy.data.cameras.remove(cam_data)
        for o, h in hidden:
            o.hide_render = h
    return str(path)
