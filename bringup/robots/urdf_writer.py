"""The URDF text the robot generators write (make_asimo_like.py, make_small_humanoid.py,
make_mesh_humanoid.py): links with <collision> elements, joints with limits, numbers as %.6g."""
import math


def f(v):
    """A number as the generators write it (%.6g)."""
    return "%.6g" % v


def xyz(v):
    return " ".join(f(x) for x in v)


def cylinder_between(a, b, r):
    """A cylinder of radius r from a to b (Reflex reads it as that capsule): (geometry XML, origin xyz,
    rpy), the rpy turning +z onto b - a (pitch about y, then yaw about z)."""
    mid = [(x + y) / 2 for x, y in zip(a, b)]
    d = [y - x for x, y in zip(a, b)]
    length = math.sqrt(sum(x * x for x in d))
    u = [x / length for x in d]
    pitch = math.acos(max(-1.0, min(1.0, u[2])))
    yaw = math.atan2(u[1], u[0]) if abs(u[2]) < 1.0 - 1e-12 else 0.0
    return '<cylinder radius="%s" length="%s"/>' % (f(r), f(length)), mid, (0, pitch, yaw)


class UrdfWriter:
    """A URDF written link by link and joint by joint; text() closes it."""

    def __init__(self, name, header, effort):
        self.parts = [header, '<robot name="%s">' % name]
        self.effort = effort  # every joint's effort limit, as written

    def link(self, name, collisions=()):
        """collisions: (geometry XML, origin xyz, rpy or None for an origin without rpy)."""
        self.parts.append('  <link name="%s">' % name)
        for i, (geometry, origin, rpy) in enumerate(collisions):
            self.parts.append('    <collision name="%s_%d">' % (name, i))
            if rpy is None:
                self.parts.append('      <origin xyz="%s"/>' % xyz(origin))
            else:
                self.parts.append('      <origin xyz="%s" rpy="%s"/>' % (xyz(origin), xyz(rpy)))
            self.parts.append('      <geometry>%s</geometry>' % geometry)
            self.parts.append('    </collision>')
        self.parts.append('  </link>')

    def joint(self, name, kind, parent, child, origin=(0, 0, 0), rpy=(0, 0, 0), axis=None, lo=None, hi=None,
              vel=None):
        self.parts.append('  <joint name="%s" type="%s">' % (name, kind))
        self.parts.append('    <parent link="%s"/><child link="%s"/>' % (parent, child))
        self.parts.append('    <origin xyz="%s" rpy="%s"/>' % (xyz(origin), xyz(rpy)))
        if axis is not None:
            self.parts.append('    <axis xyz="%s"/>' % xyz(axis))
            if kind == "continuous":
                self.parts.append('    <limit velocity="%s" effort="%s"/>' % (f(vel), self.effort))
            else:
                self.parts.append('    <limit lower="%s" upper="%s" velocity="%s" effort="%s"/>'
                                  % (f(lo), f(hi), f(vel), self.effort))
        self.parts.append('  </joint>')

    def text(self):
        return "\n".join(self.parts + ["</robot>", ""])
