# Renders a frame exported by `wisplight export --blender DIR` in Blender Cycles.
#
#   blender -b -noaudio --python DIR/scene.py -- [--output FILE.exr] [--unshadowed]
#       [--samples N] [--bounces N] [--threads N] [--seed N] [--save FILE.blend]
#
# The strands (as posed for the frame), the head, the camera, the lights, the
# fiber's width and optics are those of wisplight's frame (scene.json and the
# binary files beside this script). Hair is a Curves object of round
# ("thick") curves of the fiber's width, shaded by the Principled Hair BSDF
# (Chiang et al. 2016, as wisplight's `marschner` model). Defaults: direct
# light only (`--bounces 0`), 128 samples, linear radiance written to
# DIR/cycles.exr, or DIR/cycles-unshadowed.exr with `--unshadowed` (nothing
# casts a shadow). Coordinates are Blender's, z up: wisplight's (x, y, z) is
# (x, -z, y) here. Needs nothing beyond Blender 3.4 or newer.

import argparse
import array
import json
import math
import os
import sys

import bpy
from mathutils import Matrix, Vector

HERE = os.path.dirname(os.path.abspath(__file__))


def parse_args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    p = argparse.ArgumentParser(prog="blender -b --python scene.py --")
    p.add_argument("--output", help="picture to write (.exr, linear; .png, sRGB)")
    p.add_argument("--unshadowed", action="store_true", help="nothing casts a shadow")
    p.add_argument("--samples", type=int, default=None, help="samples per pixel")
    p.add_argument("--bounces", type=int, default=0,
                   help="light bounces; 0 (the default) is direct light only")
    p.add_argument("--threads", type=int, default=0, help="render threads; 0: all")
    p.add_argument("--seed", type=int, default=0, help="Cycles' sampling seed")
    p.add_argument("--save", help="also save the scene as this .blend file")
    p.add_argument("--no-render", action="store_true", help="build the scene only")
    return p.parse_args(argv)


def read_file(name, layout):
    """The arrays of a little-endian file, in order: (typecode, count) each."""
    out = []
    with open(os.path.join(HERE, name), "rb") as f:
        for code, count in layout:
            a = array.array(code)
            a.frombytes(f.read(count * a.itemsize))
            if len(a) != count:
                raise SystemExit(f"{name}: expected {count} values, found {len(a)}")
            if sys.byteorder != "little":
                a.byteswap()
            out.append(a)
    return out


def clear():
    for coll in (bpy.data.objects, bpy.data.meshes, bpy.data.lights, bpy.data.cameras,
                 bpy.data.materials, bpy.data.node_groups, bpy.data.worlds):
        for block in list(coll):
            coll.remove(block)


def hair_material(h):
    m = bpy.data.materials.new("wisplight_hair")
    m.use_nodes = True
    nt = m.node_tree
    nt.nodes.clear()
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    bsdf = nt.nodes.new("ShaderNodeBsdfHairPrincipled")
    fiber = h["fiber"]
    if "sigma_a" in fiber:
        bsdf.parametrization = "ABSORPTION"
        bsdf.inputs["Absorption Coefficient"].default_value = fiber["sigma_a"]
    else:
        bsdf.parametrization = "COLOR"
        bsdf.inputs["Color"].default_value = fiber["color"] + [1.0]
    bsdf.inputs["Roughness"].default_value = fiber["beta_m"]
    bsdf.inputs["Radial Roughness"].default_value = fiber["beta_n"]
    bsdf.inputs["Coat"].default_value = 0.0
    bsdf.inputs["IOR"].default_value = fiber["eta"]
    bsdf.inputs["Offset"].default_value = math.radians(fiber["alpha_deg"])
    bsdf.inputs["Random Roughness"].default_value = 0.0
    bsdf.inputs["Random Color"].default_value = 0.0
    # A fiber lets through 1 - opacity of what reaches it: the draw's
    # opacity for rays from the camera, the shadow's for every other ray.
    # Light passing among the fibers, towards a light (shadow rays) or
    # scattered on (bounces), meets them as wisplight's density map has
    # them.
    cam_op, shadow_op = h["camera_opacity"], h["shadow_opacity"]
    shader = bsdf.outputs["BSDF"]
    if cam_op < 1.0 or shadow_op < 1.0:
        path = nt.nodes.new("ShaderNodeLightPath")
        lerp = nt.nodes.new("ShaderNodeMath")
        lerp.operation = "MULTIPLY_ADD"
        nt.links.new(path.outputs["Is Camera Ray"], lerp.inputs[0])
        lerp.inputs[1].default_value = cam_op - shadow_op
        lerp.inputs[2].default_value = shadow_op
        clear_bsdf = nt.nodes.new("ShaderNodeBsdfTransparent")
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(lerp.outputs[0], mix.inputs["Fac"])
        nt.links.new(clear_bsdf.outputs["BSDF"], mix.inputs[1])
        nt.links.new(shader, mix.inputs[2])
        shader = mix.outputs["Shader"]
    nt.links.new(shader, out.inputs["Surface"])
    return m


def strands_object(h, material):
    counts, pts = read_file(h["file"], [("I", h["strands"]), ("f", 3 * h["points"])])
    edges = array.array("i")
    start = 0
    for n in counts:
        for k in range(start, start + n - 1):
            edges.append(k)
            edges.append(k + 1)
        start += n
    mesh = bpy.data.meshes.new("wisplight_strands")
    mesh.vertices.add(h["points"])
    mesh.vertices.foreach_set("co", pts)
    mesh.edges.add(len(edges) // 2)
    mesh.edges.foreach_set("vertices", edges)
    mesh.update()
    src = bpy.data.objects.new("wisplight_strands", mesh)
    bpy.context.scene.collection.objects.link(src)
    src.hide_render = True
    src.hide_viewport = True
    obj = bpy.data.objects.new("wisplight_hair", bpy.data.hair_curves.new("wisplight_hair"))
    bpy.context.scene.collection.objects.link(obj)
    # Geometry nodes turn the polylines into curves of the fiber's radius.
    ng = bpy.data.node_groups.new("wisplight_strands", "GeometryNodeTree")
    ng.outputs.new("NodeSocketGeometry", "Geometry")
    info = ng.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = src
    info.transform_space = "RELATIVE"
    gout = ng.nodes.new("NodeGroupOutput")
    to_curve = ng.nodes.new("GeometryNodeMeshToCurve")
    radius = ng.nodes.new("GeometryNodeSetCurveRadius")
    radius.inputs["Radius"].default_value = 0.5 * h["width"]
    setmat = ng.nodes.new("GeometryNodeSetMaterial")
    setmat.inputs["Material"].default_value = material
    ng.links.new(info.outputs["Geometry"], to_curve.inputs["Mesh"])
    ng.links.new(to_curve.outputs["Curve"], radius.inputs["Curve"])
    ng.links.new(radius.outputs["Curve"], setmat.inputs["Geometry"])
    ng.links.new(setmat.outputs["Geometry"], gout.inputs[0])
    mod = obj.modifiers.new("wisplight_strands", "NODES")
    mod.node_group = ng
    return obj


def head_object(hd):
    verts, tris, normals = read_file(
        hd["file"],
        [("f", 3 * hd["vertices"]), ("i", 3 * hd["triangles"]), ("f", 3 * hd["vertices"])],
    )
    mesh = bpy.data.meshes.new("wisplight_head")
    mesh.vertices.add(hd["vertices"])
    mesh.vertices.foreach_set("co", verts)
    n = hd["triangles"]
    mesh.loops.add(3 * n)
    mesh.loops.foreach_set("vertex_index", tris)
    mesh.polygons.add(n)
    mesh.polygons.foreach_set("loop_start", array.array("i", range(0, 3 * n, 3)))
    mesh.polygons.foreach_set("loop_total", array.array("i", [3]) * n)
    mesh.polygons.foreach_set("use_smooth", array.array("b", [1]) * n)
    mesh.update()
    mesh.validate()
    # wisplight's own normals, not Blender's average of the faces (custom
    # normals need auto smooth before Blender 4.1).
    if hasattr(mesh, "use_auto_smooth"):
        mesh.use_auto_smooth = True
    mesh.normals_split_custom_set_from_vertices(
        [tuple(normals[3 * i : 3 * i + 3]) for i in range(hd["vertices"])]
    )
    m = bpy.data.materials.new("wisplight_head")
    m.use_nodes = True
    bsdf = m.node_tree.nodes["Principled BSDF"]
    m.node_tree.nodes.remove(bsdf)
    diffuse = m.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = hd["color"] + [1.0]
    out = m.node_tree.nodes["Material Output"]
    m.node_tree.links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
    mesh.materials.append(m)
    obj = bpy.data.objects.new("wisplight_head", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def light_object(i, l):
    kind = l["kind"]
    data = bpy.data.lights.new(f"wisplight_light_{i}", {"directional": "SUN", "point": "POINT",
                                                         "spot": "SPOT"}[kind])
    obj = bpy.data.objects.new(f"wisplight_light_{i}", data)
    bpy.context.scene.collection.objects.link(obj)
    if kind == "directional":
        # A sun's strength is its irradiance; angle 0 is a parallel beam.
        data.energy = l["irradiance"]
        data.angle = 0.0
        obj.rotation_euler = Vector(l["direction"]).to_track_quat("-Z", "Y").to_euler()
        return obj
    # A point lamp of power P watts gives irradiance P / (4 pi r^2) (as a
    # spot does inside its cone), so wisplight's intensity I (irradiance
    # times distance squared) is P = 4 pi I. Measured: a white diffuse
    # plane 10 units under P = 400 pi shows the radiance of one under a sun
    # of strength 1 (1 / pi) to 0.1 %.
    data.energy = 4.0 * math.pi * l["intensity"]
    data.shadow_soft_size = 0.0
    obj.location = l["position"]
    if kind == "spot":
        data.spot_size = 2.0 * math.radians(l["cone_deg"])
        data.spot_blend = min(1.0, l["falloff_deg"] / l["cone_deg"])
        obj.rotation_euler = Vector(l["direction"]).to_track_quat("-Z", "Y").to_euler()
    return obj


def camera_object(c, width, height):
    data = bpy.data.cameras.new("wisplight_camera")
    data.type = "PERSP"
    data.sensor_fit = "VERTICAL"
    data.angle_y = math.radians(c["fov_deg"])
    data.clip_start = c["clip_start"]
    data.clip_end = c["clip_end"]
    obj = bpy.data.objects.new("wisplight_camera", data)
    bpy.context.scene.collection.objects.link(obj)
    r, u, f, p = (Vector(c[k]) for k in ("right", "up", "forward", "position"))
    m = Matrix.Identity(4)
    for row in range(3):
        m[row][0], m[row][1], m[row][2], m[row][3] = r[row], u[row], -f[row], p[row]
    obj.matrix_world = m
    return obj


def main():
    args = parse_args()
    with open(os.path.join(HERE, "scene.json")) as f:
        s = json.load(f)
    if s.get("format") != "wisplight-cycles-2":
        raise SystemExit("scene.json: not a wisplight export of format wisplight-cycles-2")
    clear()
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.render.resolution_x = s["width"]
    scene.render.resolution_y = s["height"]
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    scene.cycles.samples = args.samples or s["samples"]
    scene.cycles.use_adaptive_sampling = False
    scene.cycles.use_denoising = False
    scene.cycles.seed = args.seed
    b = args.bounces
    scene.cycles.max_bounces = b
    scene.cycles.diffuse_bounces = b
    scene.cycles.glossy_bounces = b
    scene.cycles.transmission_bounces = b
    scene.cycles.volume_bounces = 0
    # Shadow rays pass any number of semi-transparent fibers.
    scene.cycles.transparent_max_bounces = 1024
    scene.cycles.sample_clamp_direct = 0.0
    scene.cycles.sample_clamp_indirect = 0.0
    scene.cycles.caustics_reflective = True
    scene.cycles.caustics_refractive = True
    scene.cycles_curves.shape = "THICK"
    if args.threads > 0:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = args.threads
    # Linear radiance, no tone mapping.
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    world = bpy.data.worlds.new("wisplight_world")
    world.use_nodes = True
    # The sky: radiance `sky` from every direction, lighting the hair and
    # the head (through the hair) but not seen by the camera, whose
    # background stays black as wisplight's linear pictures have it.
    sky = float(s.get("sky", 0.0))
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = [sky, sky, sky, 1.0]
    background.inputs["Strength"].default_value = 1.0 if sky > 0.0 else 0.0
    world.cycles_visibility.camera = False
    scene.world = world
    scene.frame_current = 1

    hair = strands_object(s["hair"], hair_material(s["hair"]))
    casters = [hair]
    if s.get("head"):
        casters.append(head_object(s["head"]))
    for i, l in enumerate(s["lights"]):
        light_object(i, l)
    scene.camera = camera_object(s["camera"], s["width"], s["height"])
    if args.unshadowed:
        for obj in casters:
            obj.visible_shadow = False

    if args.save:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(args.save))
    if args.no_render:
        return
    out = args.output or os.path.join(
        HERE, "cycles-unshadowed.exr" if args.unshadowed else "cycles.exr")
    out = os.path.abspath(out)
    if out.endswith(".png"):
        scene.render.image_settings.file_format = "PNG"
        scene.render.image_settings.color_mode = "RGB"
        scene.view_settings.view_transform = "Standard"
    else:
        scene.render.image_settings.file_format = "OPEN_EXR"
        scene.render.image_settings.color_mode = "RGB"
        scene.render.image_settings.color_depth = "32"
        scene.render.image_settings.exr_codec = "ZIP"
    scene.render.filepath = out
    bpy.ops.render.render(write_still=True)
    print(f"wisplight: wrote {out}")


main()
