"""The monitor's 3D scene against independent geometry: yourdfpy's forward kinematics of the same
URDF for the body frames and the cylinder pins, and sim_core's cylinder linkage for their lengths.
A real viser server holds the scene (no browser needed)."""

import numpy as np
import pytest

from sim_core.components.cylinder import cylinder_length
from sim_core.model.spec import load_robot

pytestmark = pytest.mark.realtime

ROBOTS = ["hydrolek", "mars_nd", "harvester"]


@pytest.fixture(scope="module")
def server():
    import viser

    s = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield s
    s.stop()


def make_scene(server, robot):
    from web.scene import ArmScene

    server.scene.reset()
    return ArmScene(server, load_robot(robot))


def random_poses(tree, n, seed=1):
    rng = np.random.default_rng(seed)
    lo = np.where(np.isfinite(tree.lower), tree.lower, -np.pi)
    hi = np.where(np.isfinite(tree.upper), tree.upper, np.pi)
    return [rng.uniform(lo, hi) for _ in range(n)]


def state_for(tree, q, pressures=None):
    doc = {"pose": {name: float(v) for name, v in zip(tree.dof_names, q)}, "joints": {}}
    for j, (pa, pb) in (pressures or {}).items():
        doc["joints"][j] = {"pressure_a": pa, "pressure_b": pb}
    return doc


def world_of(handle_by_name, name):
    """World transform of a scene node, composed from the nodes' own wxyz/position up the name path."""
    import viser.transforms as tf

    T = np.eye(4)
    parts = name.strip("/").split("/")
    for k in range(len(parts)):
        h = handle_by_name.get("/" + "/".join(parts[: k + 1]))
        if h is None:
            continue
        Tk = np.eye(4)
        Tk[:3, :3] = tf.SO3(np.asarray(h.wxyz)).as_matrix()
        Tk[:3, 3] = h.position
        T = T @ Tk
    return T


@pytest.mark.parametrize("robot", ROBOTS)
def test_body_frames_match_urdf_forward_kinematics(server, robot):
    import yourdfpy

    scene = make_scene(server, robot)
    spec = scene.spec
    urdf = yourdfpy.URDF.load(str(spec.urdf_path))
    handles = {name: h for name, h in zip(scene.body_nodes, scene.frames)}
    handles["/robot"] = scene.root
    assert len(scene.frames) == spec.tree.n
    assert len(scene.meshes) == len(urdf.scene.geometry)  # every URDF visual is drawn
    for q in random_poses(spec.tree, 4):
        scene.update(state_for(spec.tree, q))
        cfg = np.array([q[spec.tree.index(n)] for n in urdf.actuated_joint_names])
        urdf.update_cfg(cfg)
        for i, link in enumerate(spec.tree.link_names):
            T_ref = urdf.get_transform(link, spec.tree.root_link)
            T = world_of(handles, scene.body_nodes[i])
            assert np.allclose(T, T_ref, atol=1e-6), f"{robot}: body of {link} drawn at the wrong pose"


@pytest.mark.parametrize("robot", ["hydrolek", "harvester"])
def test_cylinder_pins_follow_the_linkage(server, robot):
    """Pins from yourdfpy (base: parent link x joint origin; rod: child link) and the pin distance
    equal to the simulator's cylinder length L(q)."""
    import yourdfpy

    scene = make_scene(server, robot)
    spec, tree = scene.spec, scene.spec.tree
    urdf = yourdfpy.URDF.load(str(spec.urdf_path))
    cyl = [j for j in spec.joints if j.kind == "cylinder"]
    assert cyl
    for q in random_poses(tree, 5, seed=3):
        urdf.update_cfg(np.array([q[tree.index(n)] for n in urdf.actuated_joint_names]))
        pins = scene.cylinder_pins(q)
        for js in cyl:
            i = tree.index(js.dof)
            c = js.components["cylinder"]
            joint = urdf.joint_map[js.dof]
            T_base = urdf.get_transform(joint.parent, tree.root_link) @ joint.origin
            T_rod = urdf.get_transform(joint.child, tree.root_link)
            base_ref = T_base[:3, :3] @ np.array(c["base_mount"]) + T_base[:3, 3]
            rod_ref = T_rod[:3, :3] @ np.array(c["rod_mount"]) + T_rod[:3, 3]
            base, rod = pins[js.name]
            assert np.allclose(base, base_ref, atol=1e-9) and np.allclose(rod, rod_ref, atol=1e-9)
            c0, d1, d2, _, _ = c.linkage(tree.axis[i], tree.lower[i], tree.upper[i])
            L, _ = cylinder_length(q[i], c0, d1, d2)
            assert np.linalg.norm(rod - base) == pytest.approx(L, rel=1e-9)


def test_cylinder_parts_show_stroke_and_chamber_pressures(server):
    from web.colors import pressure_rgb

    scene = make_scene(server, "hydrolek")
    tree, act = scene.tree, scene.actuators
    i = tree.index("j2")
    p_sup = act.p_supply
    ia, ib, ir = (act.index[("j2", p)] for p in ("chamber_a", "chamber_b", "rod"))
    barrel = act.barrel[list(act.cyl_act).index(scene.spec.joint_names.index("j2"))]
    lengths = []
    for f in np.linspace(0.0, 1.0, 6):
        q = scene.q0.copy()
        q[i] = tree.lower[i] + f * (tree.upper[i] - tree.lower[i])
        scene.update(state_for(tree, q, {"j2": (p_sup, 0.0)}))
        scale = np.asarray(scene.batch.batched_scales)
        base, rod_pin = scene.cylinder_pins()["j2"]
        L = np.linalg.norm(rod_pin - base)
        la, lb, lr = scale[ia, 2], scale[ib, 2], scale[ir, 2]
        # barrel = chamber A + chamber B, constant; the rod reaches from the piston to the rod eye
        assert la + lb == pytest.approx(barrel, rel=1e-5)
        assert la + lr == pytest.approx(L, rel=1e-5)
        lengths.append(la)
        colours = np.asarray(scene.batch.batched_colors)
        assert (colours[ia] == pressure_rgb(p_sup, p_sup)).all() and (colours[ib] == pressure_rgb(0.0, p_sup)).all()
    # the piston travels along the barrel as the joint goes through its range (positive extends)
    assert np.all(np.diff(lengths) > 0), lengths
    assert lengths[-1] - lengths[0] > 0.5 * barrel


def test_pressure_colours():
    from web.colors import pressure_rgb

    lo, mid, hi, over = pressure_rgb([0.0, 70e5, 140e5, 300e5], 140e5)
    assert lo[2] > lo[0] + 100            # tank: blue
    assert mid[1] > mid[0] and mid[1] > mid[2]  # half supply: green
    assert hi[0] > hi[2] + 100            # supply: red
    assert (over == hi).all()             # clipped above the supply


def test_static_plant_sends_no_poses(server):
    scene = make_scene(server, "mars_nd")
    st = state_for(scene.tree, scene.q0 + 0.1)
    scene.update(st)
    sent = scene.pose_messages
    assert sent == scene.tree.n
    jitter = state_for(scene.tree, scene.q0 + 0.1 + 1e-7)
    for _ in range(5):
        scene.update(st)
        scene.update(jitter)
    assert scene.pose_messages == sent  # nothing moved visibly: nothing re-sent
    moved = scene.q0 + 0.1
    moved[3] += 0.01
    scene.update(state_for(scene.tree, moved))
    assert scene.pose_messages == sent + 1


def test_history_ring_and_reset():
    from web.history import History

    h = History(["a"], ["a"], capacity=5)
    for k in range(8):
        h.add({"time": 0.1 * k, "joints": {"a": {"requested_voltage": k, "command_voltage": k, "angle": -k}},
               "pose": {"a": -k}})
    t, v = h.series("a")
    assert np.allclose(t, [0.3, 0.4, 0.5, 0.6, 0.7]) and np.allclose(v[0], [3, 4, 5, 6, 7])
    assert not h.add({"time": 0.1 * 7, "joints": {}, "pose": {}})  # same plant time: not a new sample
    h.add({"time": 0.0, "joints": {"a": {}}, "pose": {}})        # reset: history starts afresh
    t, _ = h.series("a")
    assert np.allclose(t, [0.0])
