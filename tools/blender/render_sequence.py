"""Renders the Blender image sequence in data/sequences/blender_cornell.

Needs Blender 3.x (the shipped files were made with Blender 3.4.1). This is a
script for Blender's own Python, not for the system Python. Run it from the
repository root:

    blender -b --factory-startup -noaudio --python-exit-code 1 \\
        -P tools/blender/render_sequence.py -- [options]

Options (after the "--"): --scene (a glTF file, default
data/scenes/cornell_dynamic.gltf), --out (default
data/sequences/blender_cornell), --frames (default 8), --width and --height (in
pixels, default 64 x 48), --noisy-spp (default 4), --reference-spp (default
4096), --threads (default 2).

It imports the scene with Blender's glTF importer, numbers the mesh objects
(pass_index 1, 2, 3 ... in name order), replaces the scene's camera animation
by a keyframed orbit with a pan and a dolly, and renders frames 1..N with
Cycles on the CPU twice:

    noisy_####.exr      low spp, with Depth, Normal, Vector, IndexOB and the
                        denoising data passes (multilayer EXR, ZIP)
    reference_####.exr  high spp, Combined only (multilayer EXR, ZIP)

Colour passes are written as half floats; Blender keeps the data passes
(Depth, Normal, Vector, IndexOB, Denoising Normal, Denoising Depth) as 32-bit
floats. The seeds are fixed (and differ between the two runs), so a rerun
gives the same pixels. The files carry no date, but Cycles writes its render
times into each header, so their bytes change from run to run.
"""

import argparse
import math
import os
import sys

import numpy

# Blender 3.4's glTF importer uses numpy.bool, which NumPy 1.24 removed.
if "bool" not in vars(numpy):
    numpy.bool = bool

import bpy  # noqa: E402  (Blender's module; importable only inside Blender)

VIEW_LAYER = "ViewLayer"
NOISY_SEED = 1
REFERENCE_SEED = 7919

# Camera path, per frame after the first: the camera orbits the room centre
# to the left (towards -x), turns a little further than the orbit (a pan) and
# moves towards the centre (a dolly). The orbit uncovers the spinning box,
# which the sphere hides in the first frames. At 64 x 48 the image moves by
# up to about two pixels a frame.
ORBIT_DEG_PER_FRAME = -2.0
PAN_DEG_PER_FRAME = -1.0
DOLLY_M_PER_FRAME = 0.06


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="render_sequence.py")
    p.add_argument("--scene", default="data/scenes/cornell_dynamic.gltf")
    p.add_argument("--out", default="data/sequences/blender_cornell")
    p.add_argument("--frames", type=int, default=8)
    p.add_argument("--width", type=int, default=64)
    p.add_argument("--height", type=int, default=48)
    p.add_argument("--noisy-spp", type=int, default=4)
    p.add_argument("--reference-spp", type=int, default=4096)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args(argv)
    if min(a.frames, a.noisy_spp, a.reference_spp, a.threads) < 1 or min(a.width, a.height) < 8:
        p.error("--frames, --noisy-spp, --reference-spp and --threads must be >= 1, --width and --height >= 8")
    if not os.path.isfile(a.scene):
        p.error("no scene file " + a.scene)
    return a


def import_scene(path):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    result = bpy.ops.import_scene.gltf(filepath=os.path.abspath(path))
    if "FINISHED" not in result:
        raise RuntimeError("glTF import of %s failed: %s" % (path, result))
    scene = bpy.context.scene
    meshes = sorted((o for o in scene.objects if o.type == "MESH"), key=lambda o: o.name)
    for i, ob in enumerate(meshes, start=1):
        ob.pass_index = i
        print("pass_index %d = %s" % (i, ob.name))
    cameras = [o for o in scene.objects if o.type == "CAMERA"]
    if len(cameras) != 1:
        raise RuntimeError("expected one camera in %s, found %d" % (path, len(cameras)))
    return scene, cameras[0]


def animate_camera(scene, cam, frames):
    """Keys the camera at frames 0..frames+1, so that the first and the last
    rendered frame also have a previous and a next camera."""
    cam.animation_data_clear()  # the glTF camera animation lands in an unplayed NLA track
    cam.rotation_mode = "XYZ"
    start = cam.matrix_world.translation.copy()
    centre = (0.0, 0.0, start.z)  # the room centre, glTF (0, 1, 0), at the camera's height
    radius0 = math.hypot(start.x - centre[0], start.y - centre[1])
    for f in range(0, frames + 2):
        k = f - 1
        orbit = math.radians(ORBIT_DEG_PER_FRAME * k)
        radius = radius0 - DOLLY_M_PER_FRAME * k
        cam.location = (centre[0] + radius * math.sin(orbit), centre[1] - radius * math.cos(orbit), start.z)
        # Euler (90 deg, 0, yaw) looks along (-sin yaw, cos yaw, 0), with +Z up.
        cam.rotation_euler = (math.radians(90.0), 0.0, orbit + math.radians(PAN_DEG_PER_FRAME * k))
        cam.keyframe_insert("location", frame=f)
        cam.keyframe_insert("rotation_euler", frame=f)
    for fc in cam.animation_data.action.fcurves:
        for key in fc.keyframe_points:
            key.interpolation = "LINEAR"


def setup_render(scene, a):
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x = a.width
    r.resolution_y = a.height
    r.resolution_percentage = 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.use_motion_blur = False  # the Vector pass is only written without it
    r.film_transparent = False
    r.threads_mode = "FIXED"
    r.threads = a.threads
    # File metadata: keep frame, camera and scene; drop what changes between runs.
    r.use_stamp_date = False
    r.use_stamp_render_time = False
    r.use_stamp_memory = False
    r.use_stamp_hostname = False
    r.use_stamp_filename = False
    r.use_stamp_frame = True
    r.use_stamp_camera = True
    r.use_stamp_scene = True
    c = scene.cycles
    c.device = "CPU"
    c.use_adaptive_sampling = False
    c.use_denoising = False  # Debian's build has no denoiser; see data/sequences/README.md
    c.use_animated_seed = True
    # Blender's defaults, set here so that both runs (and reruns) agree. The
    # noisy and the reference frames share them, so they converge to the same
    # image (the indirect clamp and the glossy filter bias both alike).
    c.max_bounces = 12
    c.diffuse_bounces = 4
    c.glossy_bounces = 4
    c.transmission_bounces = 12
    c.transparent_max_bounces = 8
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 10.0
    c.blur_glossy = 1.0
    c.pixel_filter_type = "BLACKMAN_HARRIS"
    c.filter_width = 1.5
    img = r.image_settings
    img.file_format = "OPEN_EXR_MULTILAYER"
    img.exr_codec = "ZIP"
    img.color_depth = "16"
    scene.frame_start = 1
    scene.frame_end = a.frames
    scene.frame_step = 1
    vl = scene.view_layers[0]
    vl.name = VIEW_LAYER
    for other in list(scene.view_layers)[1:]:
        scene.view_layers.remove(other)
    return vl


def set_passes(vl, data):
    vl.use_pass_combined = True
    vl.use_pass_z = data
    vl.use_pass_normal = data
    vl.use_pass_vector = data
    vl.use_pass_object_index = data
    vl.cycles.denoising_store_passes = data


def render(scene, out, prefix, spp, seed):
    scene.cycles.samples = spp
    scene.cycles.seed = seed
    scene.render.filepath = os.path.join(os.path.abspath(out), prefix + "_####")
    bpy.ops.render.render(animation=True)
    for f in range(scene.frame_start, scene.frame_end + 1):
        path = scene.render.frame_path(frame=f)
        if not os.path.isfile(path):
            raise RuntimeError("Blender did not write " + path)


def main():
    a = parse_args()
    os.makedirs(a.out, exist_ok=True)
    scene, cam = import_scene(a.scene)
    scene.camera = cam
    animate_camera(scene, cam, a.frames)
    vl = setup_render(scene, a)
    set_passes(vl, True)
    render(scene, a.out, "noisy", a.noisy_spp, NOISY_SEED)
    set_passes(vl, False)
    render(scene, a.out, "reference", a.reference_spp, REFERENCE_SEED)
    print("wrote %d noisy and %d reference frames to %s" % (a.frames, a.frames, a.out))


if __name__ == "__main__":
    main()
