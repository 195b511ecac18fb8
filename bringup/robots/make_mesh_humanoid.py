#!/usr/bin/env python3
"""Writes mesh_humanoid, the humanoid whose collision geometry is meshes.

Usage: make_mesh_humanoid.py [OUTDIR]   (default: the folder of this script)

Writes into OUTDIR:
  mesh_humanoid.urdf                 the robot; collision elements are meshes (and two boxes)
  mesh_humanoid.srdf                 <disable_collisions> as MoveIt writes them
  mesh_humanoid.collision.yaml       the collision configuration (srdf: mesh_humanoid.srdf)
  mesh_humanoid.truth.yaml           the ground truth: the primitives every mesh was built from
  mesh_humanoid_description/         a ROS package (package.xml) holding meshes/*.stl, *.obj, *.dae
The fit overlay mesh_humanoid.fit.yaml is NOT written here: reflex_fit writes it from these files.

Every mesh is a tessellation of known primitives whose vertices lie ON the primitive's surface (a
capsule: rings on two hemispheres joined by the cylinder; a box: its 8 corners), so the primitive
encloses its mesh and is the ideal fit of a one-primitive link. Links built from several primitives
are non-convex (a T-shaped torso, a hand with fingers and a thumb). Formats and frames exercised:
binary STL in metres, binary STL in millimetres with scale="0.001 0.001 0.001", OBJ, COLLADA with
<up_axis>Z_UP</up_axis> in metres and in centimetres (<unit meter="0.01"/>): ROS tools ignore the up
axis and apply the unit, so every mesh is in its link frame unrotated. Paths: package:// URIs into
mesh_humanoid_description, and one plain path relative to the URDF. A fixed sensor link (imu) carries
a mesh; the torso and the feet carry boxes. No numpy: plain Python 3, same bytes on every run.
"""
import math
import os
import struct
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from urdf_writer import UrdfWriter, f, xyz  # noqa: E402  (the generators' shared writer)

PKG = "mesh_humanoid_description"
N_AROUND = 16   # vertices per ring
N_CAP = 4       # rings per hemisphere (pole excluded)


# --- geometry -------------------------------------------------------------------------------------

def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def norm(a):
    return math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def unit(a):
    n = norm(a)
    return (a[0] / n, a[1] / n, a[2] / n)


def frame(axis):
    """Two unit vectors orthogonal to axis (and to each other)."""
    helper = (1.0, 0.0, 0.0) if abs(axis[0]) < 0.9 else (0.0, 1.0, 0.0)
    e1 = unit(cross(axis, helper))
    return e1, cross(axis, e1)


def capsule_mesh(a, b, r):
    """Closed triangle mesh of the capsule a-b, radius r; every vertex on the capsule's surface.
    a == b gives a sphere."""
    d = sub(b, a)
    axis = unit(d) if norm(d) > 0 else (0.0, 0.0, 1.0)
    e1, e2 = frame(axis)
    verts, rings = [], []

    def ring(centre, radius, offset):
        start = len(verts)
        for k in range(N_AROUND):
            t = 2 * math.pi * k / N_AROUND
            c, s = math.cos(t) * radius, math.sin(t) * radius
            verts.append(tuple(centre[i] + c * e1[i] + s * e2[i] + offset * axis[i] for i in range(3)))
        rings.append(start)

    bottom_pole = len(verts)
    verts.append(tuple(a[i] - r * axis[i] for i in range(3)))
    for j in range(1, N_CAP + 1):          # hemisphere at a, from the pole to the equator
        phi = math.pi / 2 * j / N_CAP
        ring(a, r * math.sin(phi), -r * math.cos(phi))
    for j in range(N_CAP, 0, -1):          # hemisphere at b, from the equator to the pole
        phi = math.pi / 2 * j / N_CAP
        ring(b, r * math.sin(phi), r * math.cos(phi))
    top_pole = len(verts)
    verts.append(tuple(b[i] + r * axis[i] for i in range(3)))
    tris = []
    n = N_AROUND
    for k in range(n):
        tris.append((bottom_pole, rings[0] + (k + 1) % n, rings[0] + k))
        tris.append((top_pole, rings[-1] + k, rings[-1] + (k + 1) % n))
    for q in range(len(rings) - 1):
        r0, r1 = rings[q], rings[q + 1]
        for k in range(n):
            k1 = (k + 1) % n
            tris.append((r0 + k, r0 + k1, r1 + k))
            tris.append((r0 + k1, r1 + k1, r1 + k))
    return verts, tris


def box_mesh(centre, size):
    verts = [tuple(centre[i] + (0.5 if (c >> i) & 1 else -0.5) * size[i] for i in range(3)) for c in range(8)]
    tris = [(0, 2, 1), (1, 2, 3), (4, 5, 6), (5, 7, 6), (0, 1, 4), (1, 5, 4),
            (2, 6, 3), (3, 6, 7), (0, 4, 2), (2, 4, 6), (1, 3, 5), (3, 7, 5)]
    return verts, tris


def merge(*meshes):
    verts, tris = [], []
    for v, t in meshes:
        base = len(verts)
        verts += v
        tris += [(base + x, base + y, base + z) for x, y, z in t]
    return verts, tris


def scaled(mesh, s):
    v, t = mesh
    return [tuple(c * s for c in p) for p in v], t


# --- writers --------------------------------------------------------------------------------------

def write_stl(path, mesh):
    v, t = mesh
    with open(path, "wb") as fh:
        fh.write(b"mesh_humanoid generated by make_mesh_humanoid.py".ljust(80, b" "))
        fh.write(struct.pack("<I", len(t)))
        for tri in t:
            p = [v[i] for i in tri]
            n = cross(sub(p[1], p[0]), sub(p[2], p[0]))
            nn = norm(n)
            n = (n[0] / nn, n[1] / nn, n[2] / nn) if nn > 0 else (0.0, 0.0, 0.0)
            fh.write(struct.pack("<12fH", *n, *p[0], *p[1], *p[2], 0))


def write_obj(path, mesh):
    v, t = mesh
    lines = ["# mesh_humanoid generated by make_mesh_humanoid.py"]
    lines += ["v %.6f %.6f %.6f" % p for p in v]
    lines += ["f %d %d %d" % (a + 1, b + 1, c + 1) for a, b, c in t]
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")


def write_dae(path, mesh, unit_meter):
    """COLLADA 1.4.1, Z_UP, coordinates in units of `unit_meter` metres."""
    v, t = mesh
    coords = " ".join("%.6f %.6f %.6f" % p for p in v)
    idx = " ".join("%d %d %d" % tri for tri in t)
    text = """<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset>
    <contributor><authoring_tool>make_mesh_humanoid.py</authoring_tool></contributor>
    <unit name="%s" meter="%s"/>
    <up_axis>Z_UP</up_axis>
  </asset>
  <library_geometries>
    <geometry id="shape" name="shape">
      <mesh>
        <source id="shape-positions">
          <float_array id="shape-positions-array" count="%d">%s</float_array>
          <technique_common>
            <accessor source="#shape-positions-array" count="%d" stride="3">
              <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/>
            </accessor>
          </technique_common>
        </source>
        <vertices id="shape-vertices"><input semantic="POSITION" source="#shape-positions"/></vertices>
        <triangles count="%d">
          <input semantic="VERTEX" source="#shape-vertices" offset="0"/>
          <p>%s</p>
        </triangles>
      </mesh>
    </geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="scene" name="scene">
      <node id="node" name="node"><instance_geometry url="#shape"/></node>
    </visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#scene"/></scene>
</COLLADA>
""" % ("centimeter" if unit_meter == 0.01 else "meter", f(unit_meter), 3 * len(v), coords, len(v), len(t), idx)
    with open(path, "w") as fh:
        fh.write(text)


# --- the robot ------------------------------------------------------------------------------------

HEADER = """<?xml version="1.0"?>
<!-- GENERATED by make_mesh_humanoid.py: edit the script, not this file.

  mesh_humanoid: a 1.2 m humanoid whose collision geometry is meshes, the test robot of Reflex's
  mesh fitter (reflex_fit). Round dimensions chosen for this test, copied from no robot. Every mesh
  is a tessellation of known capsules, spheres and boxes (mesh_humanoid.truth.yaml), so the ideal fit
  is known. Frames: base_link is the pelvis centre, x forward, y left, z up.
  Joints (25): waist_yaw; neck_yaw, neck_pitch; per arm shoulder_pitch, shoulder_roll, arm_yaw, elbow,
  wrist_pitch; per leg hip_yaw, hip_roll, hip_pitch, knee, ankle_pitch, ankle_roll.
-->
"""


class Robot(UrdfWriter):
    def __init__(self, outdir):
        super().__init__("mesh_humanoid", HEADER, "20")
        self.outdir = outdir
        self.meshdir = os.path.join(outdir, PKG, "meshes")
        self.truth = {}

    def mesh_file(self, name, mesh, kind, unit_meter=1.0):
        path = os.path.join(self.meshdir, name)
        if kind == "stl":
            write_stl(path, mesh)
        elif kind == "obj":
            write_obj(path, mesh)
        else:
            write_dae(path, mesh, unit_meter)

    def link(self, name, elements=(), truth=()):
        """elements: (geometry XML, origin xyz); truth: generating primitives in the link frame."""
        super().link(name, [(geometry, origin, (0, 0, 0)) for geometry, origin in elements])
        if truth:
            self.truth[name] = list(truth)


def pkg(name):
    return 'package://%s/meshes/%s' % (PKG, name)


def mesh_xml(uri, scale=None):
    return '<mesh filename="%s"%s/>' % (uri, ' scale="%s"' % xyz(scale) if scale else "")


def cap(a, b, r):
    return ("capsule", a, b, r)


def build(outdir):
    os.makedirs(os.path.join(outdir, PKG, "meshes"), exist_ok=True)
    with open(os.path.join(outdir, PKG, "package.xml"), "w") as fh:
        fh.write('<?xml version="1.0"?>\n<package format="3">\n  <name>%s</name>\n  <version>0.1.0</version>\n'
                 '  <description>Collision meshes of mesh_humanoid (generated by make_mesh_humanoid.py)</description>\n'
                 '  <maintainer email="reflex@example.org">Reflex</maintainer>\n  <license>Apache-2.0</license>\n'
                 '</package>\n' % PKG)
    R = Robot(outdir)
    X, Y, Z = (1, 0, 0), (0, 1, 0), (0, 0, 1)
    zero = (0, 0, 0)
    # Pelvis: a capsule across the hips, in a Z_UP COLLADA file in metres.
    pelvis = cap((0, -0.09, 0), (0, 0.09, 0), 0.07)
    R.mesh_file("pelvis.dae", capsule_mesh(*pelvis[1:]), "dae", 1.0)
    R.link("base_link", [(mesh_xml(pkg("pelvis.dae")), zero)], [pelvis])
    # Torso: T-shaped (abdomen + chest, one binary STL, non-convex) and a backpack box.
    abdomen, chest = cap((0, 0, 0.05), (0, 0, 0.25), 0.09), cap((0, -0.10, 0.33), (0, 0.10, 0.33), 0.10)
    R.mesh_file("torso.stl", merge(capsule_mesh(*abdomen[1:]), capsule_mesh(*chest[1:])), "stl")
    backpack = ("box", (-0.15, 0, 0.30), (0.08, 0.2, 0.2))
    R.link("torso", [(mesh_xml(pkg("torso.stl")), zero), ('<box size="%s"/>' % xyz(backpack[2]), backpack[1])],
           [abdomen, chest, backpack])
    R.joint("waist_yaw", "revolute", "base_link", "torso", origin=(0, 0, 0.08), axis=Z, lo=-1.0, hi=1.0, vel=2.0)
    # A fixed sensor link with a mesh, by a plain path relative to the URDF (one rigid body with the torso).
    imu = ("sphere", (0, 0, 0), 0.03)
    R.mesh_file("imu.stl", capsule_mesh((0, 0, 0), (0, 0, 0), 0.03), "stl")
    R.link("imu_link", [(mesh_xml("%s/meshes/imu.stl" % PKG), zero)], [imu])
    R.joint("imu_fixed", "fixed", "torso", "imu_link", origin=(0.05, 0, 0.2))
    # Head: a sphere in a Z_UP COLLADA file in centimetres.
    R.link("neck")
    R.joint("neck_yaw", "revolute", "torso", "neck", origin=(0, 0, 0.45), axis=Z, lo=-1.5, hi=1.5, vel=3.0)
    head = ("sphere", (0.01, 0, 0.10), 0.10)
    R.mesh_file("head.dae", scaled(capsule_mesh(head[1], head[1], head[2]), 100.0), "dae", 0.01)
    R.link("head", [(mesh_xml(pkg("head.dae")), zero)], [head])
    R.joint("neck_pitch", "revolute", "neck", "head", axis=Y, lo=-0.5, hi=0.5, vel=3.0)
    R.link("camera_link")
    R.joint("camera_fixed", "fixed", "head", "camera_link", origin=(0.1, 0, 0.1))
    for side, s in (("l", 1.0), ("r", -1.0)):
        p = side + "_"
        R.link(p + "shoulder_link")
        R.joint(p + "shoulder_pitch", "revolute", "torso", p + "shoulder_link", origin=(0, s * 0.26, 0.36), axis=Y,
                lo=-2.0, hi=2.0, vel=3.0)
        # Upper arm: binary STL in millimetres, scale 0.001.
        upper = cap((0, 0, -0.03), (0, 0, -0.22), 0.05)
        R.mesh_file(p + "upper_arm.stl", scaled(capsule_mesh(*upper[1:]), 1000.0), "stl")
        R.link(p + "upper_arm", [(mesh_xml(pkg(p + "upper_arm.stl"), (0.001, 0.001, 0.001)), zero)], [upper])
        lo, hi = (-0.2, 1.6) if s > 0 else (-1.6, 0.2)
        R.joint(p + "shoulder_roll", "revolute", p + "shoulder_link", p + "upper_arm", axis=X, lo=lo, hi=hi, vel=3.0)
        R.link(p + "elbow_link")
        R.joint(p + "arm_yaw", "revolute", p + "upper_arm", p + "elbow_link", origin=(0, 0, -0.25), axis=Z,
                lo=-1.5, hi=1.5, vel=3.0)
        # Forearm: OBJ.
        fore = cap((0, 0, -0.03), (0, 0, -0.20), 0.04)
        R.mesh_file(p + "forearm.obj", capsule_mesh(*fore[1:]), "obj")
        R.link(p + "forearm", [(mesh_xml(pkg(p + "forearm.obj")), zero)], [fore])
        R.joint(p + "elbow", "revolute", p + "elbow_link", p + "forearm", axis=Y, lo=-2.0, hi=0.0, vel=3.0)
        # Hand: palm, three fingers and a thumb in one OBJ (non-convex).
        palm = ("box", (0, 0, -0.05), (0.03, 0.08, 0.08))
        fingers = [cap((0, y, -0.10), (0, y, -0.16), 0.01) for y in (-0.025, 0.0, 0.025)]
        thumb = cap((0.0, s * 0.045, -0.04), (0.03, s * 0.075, -0.08), 0.01)
        R.mesh_file(p + "hand.obj", merge(box_mesh(*palm[1:]), *[capsule_mesh(*c[1:]) for c in fingers + [thumb]]),
                    "obj")
        R.link(p + "hand", [(mesh_xml(pkg(p + "hand.obj")), zero)], [palm] + fingers + [thumb])
        R.joint(p + "wrist_pitch", "revolute", p + "forearm", p + "hand", origin=(0, 0, -0.23), axis=Y, lo=-1.0,
                hi=1.0, vel=4.0)
        # Leg.
        R.link(p + "hip_yaw_link")
        R.joint(p + "hip_yaw", "revolute", "base_link", p + "hip_yaw_link", origin=(0, s * 0.09, -0.1), axis=Z,
                lo=-0.6, hi=0.6, vel=3.0)
        R.link(p + "hip_roll_link")
        lo, hi = (-0.2, 0.5) if s > 0 else (-0.5, 0.2)
        R.joint(p + "hip_roll", "revolute", p + "hip_yaw_link", p + "hip_roll_link", axis=X, lo=lo, hi=hi, vel=3.0)
        # Thigh: two mesh elements (STL upper, OBJ lower), the lower one placed by its origin.
        thigh_up = cap((0, 0, -0.03), (0, 0, -0.18), 0.07)
        thigh_lo_local = cap((0, 0, 0), (0.01, 0, -0.15), 0.06)
        thigh_lo = cap((0, 0, -0.18), (0.01, 0, -0.33), 0.06)
        R.mesh_file(p + "thigh_upper.stl", capsule_mesh(*thigh_up[1:]), "stl")
        R.mesh_file(p + "thigh_lower.obj", capsule_mesh(*thigh_lo_local[1:]), "obj")
        R.link(p + "thigh", [(mesh_xml(pkg(p + "thigh_upper.stl")), zero),
                             (mesh_xml(pkg(p + "thigh_lower.obj")), (0, 0, -0.18))], [thigh_up, thigh_lo])
        R.joint(p + "hip_pitch", "revolute", p + "hip_roll_link", p + "thigh", axis=Y, lo=-1.5, hi=0.4, vel=3.0)
        shin = cap((0, 0, -0.04), (0, 0, -0.32), 0.055)
        R.mesh_file(p + "shin.stl", capsule_mesh(*shin[1:]), "stl")
        R.link(p + "shin", [(mesh_xml(pkg(p + "shin.stl")), zero)], [shin])
        R.joint(p + "knee", "revolute", p + "thigh", p + "shin", origin=(0, 0, -0.38), axis=Y, lo=0.0, hi=2.0, vel=3.0)
        R.link(p + "ankle_link")
        R.joint(p + "ankle_pitch", "revolute", p + "shin", p + "ankle_link", origin=(0, 0, -0.38), axis=Y, lo=-1.0,
                hi=0.8, vel=3.0)
        # Foot: a box (fitted like a mesh when the robot has a fit overlay).
        foot = ("box", (0.04, 0, -0.05), (0.22, 0.1, 0.04))
        R.link(p + "foot", [('<box size="%s"/>' % xyz(foot[2]), foot[1])], [foot])
        R.joint(p + "ankle_roll", "revolute", p + "ankle_link", p + "foot", axis=X, lo=-0.4, hi=0.4, vel=3.0)
    with open(os.path.join(outdir, "mesh_humanoid.urdf"), "w") as fh:
        fh.write(R.text())
    # SRDF, as MoveIt's setup assistant writes it (an entry naming a link without geometry included).
    srdf = ['<?xml version="1.0"?>', '<!-- GENERATED by make_mesh_humanoid.py -->', '<robot name="mesh_humanoid">',
            '  <disable_collisions link1="head" link2="base_link" reason="Never"/>',
            '  <disable_collisions link1="head" link2="l_shin" reason="Never"/>',
            '  <disable_collisions link1="head" link2="r_shin" reason="Never"/>',
            '  <disable_collisions link1="camera_link" link2="torso" reason="Adjacent"/>',
            '</robot>', '']
    with open(os.path.join(outdir, "mesh_humanoid.srdf"), "w") as fh:
        fh.write("\n".join(srdf))
    with open(os.path.join(outdir, "mesh_humanoid.collision.yaml"), "w") as fh:
        fh.write("# GENERATED by make_mesh_humanoid.py. Collision configuration of mesh_humanoid.urdf.\n"
                 "# The fit overlay is mesh_humanoid.fit.yaml (default location; written by reflex_fit).\n"
                 "exclude_adjacent: true\nsrdf: mesh_humanoid.srdf\n")
    truth = ["# GENERATED by make_mesh_humanoid.py: the primitives every collision mesh (and box) was built",
             "# from, in the link frame (m). Mesh vertices lie on their surfaces.", "links:"]
    for link in sorted(R.truth):
        truth.append("  %s:" % link)
        for prim in R.truth[link]:
            if prim[0] == "capsule":
                truth.append("    - {capsule: [[%s], [%s]], radius: %s}" % (
                    ", ".join(f(c) for c in prim[1]), ", ".join(f(c) for c in prim[2]), f(prim[3])))
            elif prim[0] == "sphere":
                truth.append("    - {sphere: [%s], radius: %s}" % (", ".join(f(c) for c in prim[1]), f(prim[2])))
            else:
                truth.append("    - {box: [%s], size: [%s]}" % (", ".join(f(c) for c in prim[1]),
                                                              ", ".join(f(c) for c in prim[2])))
    with open(os.path.join(outdir, "mesh_humanoid.truth.yaml"), "w") as fh:
        fh.write("\n".join(truth) + "\n")


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        sys.exit(0)
    out = sys.argv[1] if len(sys.argv) > 1 else os.path.dirname(os.path.abspath(__file__))
    build(out)
    print("wrote mesh_humanoid into", out)
