"""The 3D scene: the robot from the simulator's URDF, its cylinders between their mounting points,
and the chamber pressures as colour.

Robot: one viser frame per moving body (the sim_core :class:`KinematicTree`, so bodies joined by
fixed joints move as one, exactly as the simulator sees them), nested as the tree is; the URDF's
visual geometry (parsed by yourdfpy, with its materials) hangs under those frames. A pose update
sends one orientation per moving joint: the joint origin is fixed in its parent, only the rotation
``R_tree Rot(axis, q)`` changes. (``viser.extras.ViserUrdf.update_cfg`` re-sends every frame,
fixed ones included, through trimesh's scene graph: 2-7 ms CPU per update here against 0.7-1.4 ms
for this with actuators; ``python -m web.bench``.)

Actuators: one batched mesh (a unit cylinder instanced, so a whole robot is 4 messages per frame):

* a hydraulic cylinder is drawn from its base pin (fixed to the parent body, in the joint frame
  before the joint rotation) to its rod-eye pin (in the child body frame), at the length the
  simulator's linkage gives; the barrel hangs from the base pin, the rod from the rod eye, and the
  barrel is split at the piston into the cap chamber (A) and the rod chamber (B), each coloured by
  its pressure, so the stroke shows as the piston moving along the barrel; two dark lugs join the
  joint axis to the pins (the linkage triangle that turns stroke into joint rotation);
* a rotary actuator or motor is two discs on the joint axis, one per chamber/port.
"""

from __future__ import annotations

import threading

import numpy as np

from sim_core.dynamics.rigid_body import RigidBodyModel

from .colors import pressure_rgb

STEEL = np.array([200, 205, 212], dtype=np.uint8)
LUG = np.array([90, 92, 98], dtype=np.uint8)
MOVE_EPS = 1e-5  # rad: joint motion below this is not re-sent (invisible, and the plant never stands quite still)
ROOT = "/robot"
ACTUATORS = "/actuators"


def quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix."""
    m = R
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    return q / np.linalg.norm(q)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternion arrays [..., 4] (w, x, y, z)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_z_to(u: np.ndarray) -> np.ndarray:
    """Quaternions [n, 4] of the shortest rotations taking +z onto the unit vectors ``u`` [n, 3]."""
    w = 1.0 + u[:, 2]
    q = np.stack([w, -u[:, 1], u[:, 0], np.zeros(len(u))], axis=1)
    flip = w < 1e-9  # u = -z: any half turn about a horizontal axis
    q[flip] = (0.0, 1.0, 0.0, 0.0)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def unit_cylinder():
    """Vertices and faces of a cylinder of radius 1 and height 1 along z, centred at the origin."""
    import trimesh

    m = trimesh.creation.cylinder(radius=1.0, height=1.0, sections=24)
    return np.asarray(m.vertices, dtype=np.float32), np.asarray(m.faces, dtype=np.uint32)


class ActuatorGeometry:
    """Where each actuator's parts are, from the robot spec; ``parts(Rw, ow, q)`` places them."""

    def __init__(self, spec, extent: float):
        tree = spec.tree
        self.p_supply = float(spec.supply["pressure"])
        cyl, rot = [], []
        for a, js in enumerate(spec.joints):
            i = tree.index(js.dof)
            if js.kind == "cylinder" and js.components["cylinder"].direct:
                continue    # acts along the prismatic joint: the moving link shows it
            if js.kind == "cylinder":
                c = js.components["cylinder"]
                _, _, _, l_min, stroke = c.linkage(tree.axis[i], tree.lower[i], tree.upper[i])
                barrel = min(max(stroke + 0.06 * l_min, 0.55 * l_min), 0.94 * l_min)
                rod = min(l_min + stroke - barrel + 0.04 * l_min, 0.97 * l_min)
                cyl.append(dict(act=a, body=i, parent=int(tree.parent[i]), base=np.array(c["base_mount"], float),
                                rod_mount=np.array(c["rod_mount"], float), barrel=barrel, rod=rod,
                                r_barrel=0.75 * c["bore"], r_rod=0.5 * c["rod_diameter"]))
            else:  # a housing sized by the displacement the joint sees (motor displacement x gear)
                r = js.components["rotary"]
                size = 1.2 * (2.0 * np.pi * r["displacement"] * r["gear_ratio"]) ** (1.0 / 3.0)
                size = float(np.clip(size, 0.01 * extent, 0.06 * extent))
                rot.append(dict(act=a, body=i, radius=size, thick=0.45 * size))
        self.cyl, self.rot = cyl, rot
        self.R_tree, self.p_tree, self.axis = tree.R_tree, tree.p_tree, tree.axis
        nc = len(cyl)
        self.cyl_act = np.array([c["act"] for c in cyl], dtype=int)
        self.cyl_body = np.array([c["body"] for c in cyl], dtype=int)
        self.cyl_parent = np.array([c["parent"] for c in cyl], dtype=int)
        self.base = np.array([c["base"] for c in cyl]).reshape(nc, 3)
        self.rod_mount = np.array([c["rod_mount"] for c in cyl]).reshape(nc, 3)
        self.barrel = np.array([c["barrel"] for c in cyl])
        self.rod = np.array([c["rod"] for c in cyl])
        self.r_barrel = np.array([c["r_barrel"] for c in cyl])
        self.r_rod = np.array([c["r_rod"] for c in cyl])
        self.r_lug = 0.6 * self.r_rod
        self.rot_act = np.array([r["act"] for r in rot], dtype=int)
        self.rot_body = np.array([r["body"] for r in rot], dtype=int)
        self.rot_r = np.array([r["radius"] for r in rot])
        self.rot_h = np.array([r["thick"] for r in rot])
        self.n_instances = 5 * nc + 2 * len(rot)
        # instance index of each part: (joint, part) -> row of the batched mesh
        names = [js.name for js in spec.joints]
        self.index: dict[tuple[str, str], int] = {}
        for k, part in enumerate(("chamber_a", "chamber_b", "rod", "base_lug", "rod_lug")):
            for n, c in enumerate(cyl):
                self.index[(names[c["act"]], part)] = k * nc + n
        for k, part in enumerate(("port_a", "port_b")):
            for n, r in enumerate(rot):
                self.index[(names[r["act"]], part)] = 5 * nc + k * len(rot) + n

    def mounts(self, Rw: np.ndarray, ow: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World positions [n_cyl, 3] of every cylinder's base pin and rod-eye pin."""
        i, p = self.cyl_body, self.cyl_parent
        R_pre = np.where((p >= 0)[:, None, None], Rw[np.maximum(p, 0)], np.eye(3)) @ self.R_tree[i]
        base = ow[i] + np.einsum("nij,nj->ni", R_pre, self.base)
        rod = ow[i] + np.einsum("nij,nj->ni", Rw[i], self.rod_mount)
        return base, rod

    def parts(self, Rw, ow, p_a, p_b):
        """Instance positions, quaternions, per-axis scales and colours of every actuator part."""
        return (*self.geometry(Rw, ow), self.colours(p_a, p_b))

    def geometry(self, Rw, ow):
        """Instance positions, quaternions and per-axis scales (float32) at the body poses ``Rw``, ``ow``."""
        pos, quat, scale = [], [], []
        if len(self.cyl):
            base, rod_pin = self.mounts(Rw, ow)
            d = rod_pin - base
            L = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
            u = d / L[:, None]
            q = quat_z_to(u)
            piston = np.clip(L - self.rod, 1e-4, self.barrel - 1e-4)  # from the base pin
            segs = (  # (start, end) along the axis from the base pin, radius: chamber A, chamber B, rod
                (np.zeros_like(L), piston, self.r_barrel),
                (piston, self.barrel, self.r_barrel),
                (piston, L, self.r_rod),
            )
            for s0, s1, r in segs:
                pos.append(base + u * (0.5 * (s0 + s1))[:, None])
                quat.append(q)
                scale.append(np.stack([r, r, np.maximum(s1 - s0, 1e-4)], axis=1))
            # lugs: joint axis -> each pin (the linkage triangle that turns stroke into rotation)
            pivot = ow[self.cyl_body]
            for pin in (base, rod_pin):
                d = pin - pivot
                n = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
                pos.append(pivot + 0.5 * d)
                quat.append(quat_z_to(d / n[:, None]))
                scale.append(np.stack([self.r_lug, self.r_lug, n], axis=1))
        if len(self.rot):
            i = self.rot_body
            ax = np.einsum("nij,nj->ni", Rw[i], self.axis[i])
            q = quat_z_to(ax)
            for sign in (1.0, -1.0):  # port A disc, port B disc
                pos.append(ow[i] + sign * ax * (0.5 * self.rot_h)[:, None])
                quat.append(q)
                scale.append(np.stack([self.rot_r, self.rot_r, self.rot_h], axis=1))
        return (np.concatenate(pos).astype(np.float32), np.concatenate(quat).astype(np.float32),
                np.concatenate(scale).astype(np.float32))

    def colours(self, p_a, p_b) -> np.ndarray:
        """Instance colours (uint8 RGB): chambers and ports by pressure, rods and lugs fixed."""
        nc = len(self.cyl)
        if not hasattr(self, "_col"):
            self._col = np.zeros((self.n_instances, 3), dtype=np.uint8)
            self._col[2 * nc:3 * nc] = STEEL
            self._col[3 * nc:5 * nc] = LUG
        p = np.concatenate([p_a[self.cyl_act], p_b[self.cyl_act], p_a[self.rot_act], p_b[self.rot_act]])
        rgb = pressure_rgb(p, self.p_supply)
        col = self._col.copy()
        col[:2 * nc] = rgb[:2 * nc]
        col[5 * nc:] = rgb[2 * nc:]
        return col


class ArmScene:
    """The robot and its actuators in a viser scene; :meth:`update` draws one plant state."""

    def __init__(self, server, spec):
        import yourdfpy

        self.server = server
        self.spec = spec
        tree = self.tree = spec.tree
        self.model = RigidBodyModel(tree)
        self.q0 = self._initial_pose(spec)
        self._lock = threading.Lock()
        urdf = yourdfpy.URDF.load(str(spec.urdf_path), build_scene_graph=True, load_meshes=True,
                                  build_collision_scene_graph=False, load_collision_meshes=False)
        # one frame per moving body, nested like the tree
        self.body_nodes: list[str] = []
        self._q_tree = np.array([quat_from_matrix(R) for R in tree.R_tree]).reshape(tree.n, 4)
        q_init = self._body_quats(self.q0)
        self.root = server.scene.add_frame(ROOT, show_axes=False)
        self.frames = []
        for i in range(tree.n):
            par = ROOT if tree.parent[i] < 0 else self.body_nodes[tree.parent[i]]
            name = f"{par}/{tree.link_names[i]}"
            self.body_nodes.append(name)
            self.frames.append(server.scene.add_frame(name, show_axes=False, wxyz=q_init[i],
                                                      position=tree.p_tree[i]))
        # the URDF's visual geometry, in its body's frame
        scene = urdf.scene
        self.meshes = []
        self._mesh_points: list[tuple[int, np.ndarray]] = []
        for k, (gname, mesh) in enumerate(scene.geometry.items()):
            link = scene.graph.transforms.parents[gname]
            body, R, p = tree.link_frames[link]
            T = np.eye(4)
            T[:3, :3], T[:3, 3] = R, p
            mesh = mesh.copy()
            mesh.apply_transform(T @ urdf.get_transform(gname, link))
            node = ROOT if body < 0 else self.body_nodes[body]
            self.meshes.append(server.scene.add_mesh_trimesh(f"{node}/visual_{k}", mesh))
            self._mesh_points.append((body, np.asarray(mesh.bounds)))
        self.bounds = self.workspace_bounds()
        self.extent = float(np.max(self.bounds[1] - self.bounds[0]))
        Rw, ow = self.model.frames(self.q0)
        # actuators
        self.actuators = ActuatorGeometry(spec, self.extent)
        self.joint_names = spec.joint_names
        self.dof_of_joint = [tree.index(j.dof) for j in spec.joints]
        self.batch = None
        if self.actuators.n_instances:
            verts, faces = unit_cylinder()
            pa = np.full(len(spec.joints), 0.5 * self.actuators.p_supply)
            pos, quat, scale, col = self.actuators.parts(Rw, ow, pa, pa)
            self.batch = server.scene.add_batched_meshes_simple(
                ACTUATORS, verts, faces, batched_wxyzs=quat, batched_positions=pos, batched_scales=scale,
                batched_colors=col, lod="off", cast_shadow=False, receive_shadow=False)
        # bookkeeping for tests and the panel
        self._sent_q = self.q0.copy()
        self.pose_messages = 0
        self.updates = 0
        self.last_q = self.q0.copy()
        self.last_update = 0.0

    def geometry_bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World bounding box of the robot's visual geometry (mesh boxes) at ``q``."""
        Rw, ow = self.model.frames(q)
        pts = []
        for body, (lo, hi) in self._mesh_points:
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            pts.append(corners if body < 0 else corners @ Rw[body].T + ow[body])
        pts = np.concatenate(pts)
        return pts.min(axis=0), pts.max(axis=0)

    def workspace_bounds(self, samples: int = 32, spread: float = 0.15) -> tuple[np.ndarray, np.ndarray]:
        """Bounding box of the geometry at the initial pose and at poses around it (each joint within
        ``spread`` of its range), which is what the default camera frames."""
        tree = self.tree
        rng = np.random.default_rng(0)
        span = np.where(np.isfinite(tree.upper - tree.lower), tree.upper - tree.lower, 2.0 * np.pi)
        lo, hi = self.geometry_bounds(self.q0)
        for _ in range(samples):
            q = self.q0 + rng.uniform(-spread, spread, tree.n) * span
            q = np.clip(q, tree.lower, tree.upper)
            a, b = self.geometry_bounds(q)
            lo, hi = np.minimum(lo, a), np.maximum(hi, b)
        return lo, hi

    @staticmethod
    def _initial_pose(spec) -> np.ndarray:
        q = np.zeros(spec.tree.n)
        for js in spec.joints:
            q[spec.tree.index(js.dof)] = js.settings["initial_position"]
        for dof, s in spec.passive.items():
            q[spec.tree.index(dof)] = s["initial_position"]
        return q

    def _body_quats(self, q: np.ndarray) -> np.ndarray:
        h = 0.5 * q
        qa = np.concatenate([np.cos(h)[:, None], np.sin(h)[:, None] * self.tree.axis], axis=1)
        return quat_mul(self._q_tree, qa)

    def pose_vector(self, pose: dict) -> np.ndarray:
        """Tree-ordered joint angles from a state document's ``pose`` (missing joints keep their last value)."""
        q = self.last_q.copy()
        for i, name in enumerate(self.tree.dof_names):
            v = pose.get(name)
            if v is not None:
                q[i] = v
        return q

    def update(self, state: dict) -> None:
        """Draw one state document (``pose`` and per-joint chamber pressures).

        Only joints that moved more than :data:`MOVE_EPS` since they were last sent are re-sent; the
        actuator instances follow when any joint moved; colours go out when a pressure colour changed.
        """
        import time

        q = self.pose_vector(state.get("pose", {}))
        joints = state.get("joints", {})
        p_a = np.array([joints.get(j, {}).get("pressure_a", 0.0) for j in self.joint_names], dtype=float)
        p_b = np.array([joints.get(j, {}).get("pressure_b", 0.0) for j in self.joint_names], dtype=float)
        moved = np.abs(q - self._sent_q) > MOVE_EPS
        # atomic: the browser applies pose and cylinders together, and viser wakes its loop once per frame
        with self._lock, self.server.atomic():
            if moved.any():
                quats = self._body_quats(q)
                for i in np.flatnonzero(moved):
                    self.frames[i].wxyz = quats[i]
                self._sent_q[moved] = q[moved]
                self.pose_messages += int(moved.sum())
            if self.batch is not None:
                if moved.any():
                    pos, quat, scale = self.actuators.geometry(*self.model.frames(self._sent_q))
                    self.batch.batched_positions = pos
                    self.batch.batched_wxyzs = quat
                    self.batch.batched_scales = scale
                self.batch.batched_colors = self.actuators.colours(p_a, p_b)  # sent only if a colour changed
            self.last_q = q
            self.updates += 1
            self.last_update = time.monotonic()

    def set_visible(self, links: bool | None = None, actuators: bool | None = None) -> None:
        """Show or hide the robot's links and its actuators (the grid stays)."""
        if links is not None:
            self.root.visible = bool(links)
        if actuators is not None and self.batch is not None:
            self.batch.visible = bool(actuators)

    def cylinder_pins(self, q: np.ndarray | None = None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """World positions of each cylinder's base pin and rod-eye pin at ``q`` (default: last drawn)."""
        Rw, ow = self.model.frames(self.last_q if q is None else q)
        base, rod = self.actuators.mounts(Rw, ow)
        return {self.joint_names[a]: (base[k], rod[k]) for k, a in enumerate(self.actuators.cyl_act)}

    def points_of_interest(self, q: np.ndarray | None = None) -> np.ndarray:
        """World points that outline the arm: every body origin and every cylinder pin."""
        Rw, ow = self.model.frames(self.last_q if q is None else q)
        pts = [ow]
        if len(self.actuators.cyl):
            pts.extend(self.actuators.mounts(Rw, ow))
        return np.concatenate(pts)
