"""The Python bindings against the C++ paths they wrap: the same models, numbers and errors."""
import os
import subprocess

import numpy as np
import pytest

import inhand

BINARY = os.environ.get("INHAND_BINARY", "inhand")
# The kinematic simulator (physics off): these tests are of the bindings, not of the hand.
FAST = {"voxel_m": 0.003, "max_views": 2, "planner": {"directions": 80, "rolls": 4},
        "sim": {"frame_subsample": 8, "physics": {"enabled": False}}}


def read_ply_vertices(path):
    """x, y, z, variance of a binary little-endian PLY as inhand writes it (an independent
    reader: numpy on the bytes)."""
    with open(path, "rb") as f:
        data = f.read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    count = int(next(l for l in header if l.startswith("element vertex")).split()[2])
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("variance", "<f4"),
                      ("r", "u1"), ("g", "u1"), ("b", "u1")])
    v = np.frombuffer(data, dtype=dtype, count=count, offset=end)
    return np.stack([v["x"], v["y"], v["z"]], axis=1), v["variance"]


@pytest.fixture(scope="module")
def frames_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("render") / "frames"
    subprocess.run([BINARY, "render", "--object", "builtin:pill_bottle", "--views", "8",
                    "--out", str(out)], check=True, capture_output=True)
    return str(out)


def test_frames_are_float32_metres_with_rigid_poses(frames_dir):
    frames = inhand.load_frames(frames_dir)
    assert len(frames) == 8
    f = frames[-1]
    assert f.depth_m.dtype == np.float32 and f.depth_m.shape == (480, 640)
    assert f.depth_m.flags["C_CONTIGUOUS"]
    valid = f.depth_m[f.depth_m > 0]
    assert 0.6 < valid.min() < 0.7  # metres: the bottle 0.7 m away, at most 6 cm nearer
    R = f.T_O_C[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
    assert frames.camera.width == 640 and frames.camera.fx == pytest.approx(525)
    np.testing.assert_allclose(frames.bounds_max - frames.bounds_min, [0.08, 0.08, 0.12], atol=1e-6)
    with pytest.raises(IndexError):
        frames[8]


def test_frames_from_a_robot_carry_joints_camera_and_grasp(frames_dir, tmp_path):
    """frames.json with the robot's fields (q, T_B_C, T_O_palm at the top) and no T_O_C: the
    frames give them back as they were written; plain fuse refuses them by frame."""
    import json
    import shutil
    robot_dir = tmp_path / "robot_frames"
    shutil.copytree(frames_dir, robot_dir)
    with open(robot_dir / "frames.json") as f:
        j = json.load(f)
    T_B_C = np.eye(4)
    T_B_C[:3, 3] = [0.1, -0.2, 0.3]
    T_O_palm = np.eye(4)
    T_O_palm[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    j["T_O_palm"] = T_O_palm.flatten().tolist()
    for k, fr in enumerate(j["frames"]):
        del fr["T_O_C"]
        fr["q"] = {"j1": 0.25 * k, "j2": -1.0}
        fr["T_B_C"] = T_B_C.flatten().tolist()
    with open(robot_dir / "frames.json", "w") as f:
        json.dump(j, f)
    frames = inhand.load_frames(str(robot_dir))
    f = frames[3]
    assert f.T_O_C is None
    assert f.q == {"j1": 0.75, "j2": -1.0}
    np.testing.assert_array_equal(f.T_B_C, T_B_C)
    np.testing.assert_array_equal(f.T_O_palm, T_O_palm)
    r = subprocess.run([BINARY, "fuse", "--frames", str(robot_dir), "--out",
                        str(tmp_path / "m.ply")], capture_output=True, text=True)
    assert r.returncode == 1 and "frames[0] has no T_O_C" in r.stderr
    assert not (tmp_path / "m.ply").exists()


def test_volume_from_python_equals_inhand_fuse(frames_dir, tmp_path):
    cli_ply = str(tmp_path / "cli.ply")
    subprocess.run([BINARY, "fuse", "--frames", frames_dir, "--out", cli_ply], check=True,
                   capture_output=True)
    frames = inhand.load_frames(frames_dir)
    volume = inhand.Volume(frames.bounds_min, frames.bounds_max, voxel_m=0.002)
    for f in frames:
        volume.integrate(f.depth_m, f.T_O_C, frames.camera)
    model = volume.extract()
    vertices, variance = read_ply_vertices(cli_ply)
    assert model.vertices.shape == vertices.shape
    np.testing.assert_array_equal(model.vertices, vertices)
    np.testing.assert_array_equal(model.variance, variance)
    # The arrays are views of the model (no copies), and the PLY it saves is the CLI's.
    assert not model.vertices.flags["OWNDATA"] and model.vertices.dtype == np.float32
    assert model.faces.dtype == np.int32 and model.faces.max() < len(model.vertices)
    py_ply = str(tmp_path / "py.ply")
    model.save_ply(py_ply)
    np.testing.assert_array_equal(read_ply_vertices(py_ply)[0], vertices)
    # The observed surface alone: the measured triangles.
    observed = volume.extract(surface="observed")
    assert len(observed.vertices) <= len(model.vertices)
    assert observed.observed.all()


def test_errors_name_the_field(frames_dir, tmp_path):
    missing = str(tmp_path / "nowhere")
    with pytest.raises(inhand.Error, match="nowhere"):
        inhand.load_frames(missing)
    with pytest.raises(inhand.Error, match="bounds_max must exceed bounds_min"):
        inhand.Volume(np.zeros(3), np.zeros(3))
    volume = inhand.Volume(np.full(3, -0.1), np.full(3, 0.1), voxel_m=0.004)
    camera = inhand.Camera()
    with pytest.raises(inhand.Error, match="320x240 pixels, the camera's are 640x480"):
        volume.integrate(np.zeros((240, 320), np.float32), np.eye(4), camera)
    skew = np.eye(4)
    skew[0, 1] = 0.5
    with pytest.raises(inhand.Error, match="T_O_C: not a rigid transform: rotation part is not orthonormal"):
        volume.integrate(np.zeros((480, 640), np.float32), skew, camera)
    with pytest.raises(inhand.Error, match="surface: must be closed or observed"):
        volume.extract(surface="open")
    robot = inhand.Robot.load()
    with pytest.raises(inhand.Error, match=r"options.planner: unknown option \"t_qq\""):
        inhand.ScanSession(robot, np.zeros(3), options={"planner": {"t_qq": 1}})
    with pytest.raises(inhand.Error, match="no grasp"):
        inhand.ScanSession(robot, np.zeros(3)).next_view(robot.home())
    with pytest.raises(inhand.Error, match="absent.json: no such file"):
        inhand.Robot.load(str(tmp_path / "absent.json"))


def drive(session, sim):
    """runGraspViews in Python."""
    sim.point_camera(session.camera_pose())
    while (view := session.next_view(sim.q)) is not None:
        sim.execute(view.waypoints,
                    lambda q: session.add_frame(sim.capture(), q, sim.camera_pose()))
        session.finish_view()
        session.add_joint_torques(sim.q, sim.joint_torques())  # at rest: they weigh the object
    return session.summary().termination


def test_session_driven_from_python_equals_the_cpp_scan(tmp_path):
    """One grasp of the coffee can held at the simulator's grasp: the loop in Python gives the
    model inhand.scan (the C++ driver) gives, vertex for vertex; a checkpoint saved midway and
    loaded gives it too."""
    options = dict(FAST, start="held", tracking={"enabled": False})
    robot = inhand.Robot.load()
    cpp = inhand.scan("builtin:coffee_can", robot=robot, options=options, max_grasps=1)

    sim = inhand.Simulator(robot, "builtin:coffee_can", options=options, start="held")
    T = sim.grasp_T_O_palm
    centre = T[:3, :3] @ [0, 0, robot.grasp_offset] + T[:3, 3]
    session = inhand.ScanSession(robot, centre, options=options)
    session.begin_grasp(T, sim.q)
    sim.point_camera(session.camera_pose())
    view = session.next_view(sim.q)
    reports = []
    sim.execute(view.waypoints,
                lambda q: reports.append(session.add_frame(sim.capture(), q, sim.camera_pose())))
    assert reports and all(r["fused"] for r in reports)  # no tracking: every frame as reported
    np.testing.assert_allclose(reports[-1]["T_B_C"], sim.camera_pose(), atol=1e-12)
    session.finish_view()
    checkpoint = str(tmp_path / "scan.inhand")
    session.save(checkpoint)
    resumed = inhand.ScanSession.load(checkpoint, robot, options=options)
    assert resumed.summary().frames == session.summary().frames
    termination = drive(resumed, sim)

    assert termination == cpp.termination
    payload = resumed.summary().payload  # weighed at the end of each view driven in Python
    assert payload["readings"] >= 2
    assert abs(payload["mass_kg"] - sim.object_mass_kg) < 0.1 * sim.object_mass_kg
    model = resumed.model()
    np.testing.assert_array_equal(model.vertices, cpp.model.vertices)
    np.testing.assert_array_equal(model.variance, cpp.model.variance)
    assert [v["frames"] for v in resumed.views] == [v["frames"] for v in cpp.views]
    assert cpp.coverage > 0.5
    # Each Alg. 1 view met the threshold in force, and the unresolved information fell.
    for v in cpp.views:
        if not v["initial"]:
            assert v["predicted_gain"] >= v["t_q"] > 0
    assert cpp.views[-1]["unresolved"] < cpp.views[0]["unresolved"]


def test_colours_reach_numpy_without_copies():
    """A scan with the colour camera: the model's N x 4 colours are a view of its memory, most
    of the observed vertices have colour, and they are the checkerboard's red and cream, not
    grey."""
    options = dict(FAST, start="held", sim=dict(FAST["sim"], colour={"enabled": True}))
    result = inhand.scan("builtin:coffee_can", options=options, max_grasps=1)
    model = result.model
    rgba = model.rgba
    assert rgba.shape == (len(model.vertices), 4) and rgba.dtype == np.uint8
    assert not rgba.flags.owndata  # a view of the model's memory
    seen = rgba[:, 3] == 255
    assert seen[model.observed == 1].mean() > 0.8
    red = rgba[seen, 0].astype(int) - rgba[seen, 1].astype(int)
    assert (red > 60).mean() > 0.2  # the red squares (200, 40, 40 before shading)
    without = inhand.scan("builtin:coffee_can", options=dict(FAST, start="held"), max_grasps=1)
    assert without.model.rgba.shape == (0, 4)
