"""inhand: autonomous in-hand 3D modelling of unknown objects (Krainin, Curless, Fox, ICRA 2011).

Poses are 4x4 numpy arrays, joint states 1-D float64 arrays, depth images HxW float32 arrays in
metres (0: no return). Errors raise inhand.Error (a RuntimeError) naming the file or field.

    frames = inhand.load_frames("frames")          # recorded depth frames with camera poses
    volume = inhand.Volume(frames.bounds_min, frames.bounds_max, voxel_m=0.002)
    for f in frames:
        volume.integrate(f.depth_m, f.T_O_C, frames.camera)
    volume.extract().save_ply("model.ply")

    robot = inhand.Robot.load()                    # the WAM with BarrettHand (or your config)
    session = inhand.ScanSession(robot, centre)    # the scan, driven from your own loop
    session.begin_grasp(T_O_palm, q)
    while (view := session.next_view(q_now)) is not None:
        ... move along view.waypoints, session.add_frame(depth_m, q, T_B_C) for each frame ...
        session.finish_view()
"""
import os as _os

from ._inhand import (Camera, Error, Frames, GraspCandidate, Model, PlannedView, Robot,
                      ScanResult, ScanSession, Simulator, Summary, Volume, load_frames, scan)
from . import _inhand

__all__ = ["Camera", "Error", "Frames", "GraspCandidate", "Model", "PlannedView", "Robot",
           "ScanResult", "ScanSession", "Simulator", "Summary", "Volume", "load_frames", "scan",
           "data_dir"]


def data_dir():
    """The robot configs and meshes: $INHAND_DATA_DIR, the installed share/inhand/data, or the
    source tree's data/."""
    env = _os.environ.get("INHAND_DATA_DIR")
    if env:
        return env
    here = _os.path.dirname(_os.path.abspath(__file__))
    for up in (3, 4):  # PREFIX/lib/python3/dist-packages/inhand or PREFIX/lib/pythonX.Y/...
        installed = _os.path.join(here, *([".."] * up), "share", "inhand", "data")
        if _os.path.isdir(installed):
            return _os.path.normpath(installed)
    return _inhand._built_in_data_dir()


_inhand._set_data_dir(data_dir())
